"""`ball_tracker` node (issue #5)."""
from ball_balance.nodes.pending import exit_not_implemented


def main(args=None):
    exit_not_implemented("ball_tracker", 5)
