"""`ball_balance_visualizer` node (issue #6)."""
from ball_balance.nodes.pending import exit_not_implemented


def main(args=None):
    exit_not_implemented("ball_balance_visualizer", 6)
