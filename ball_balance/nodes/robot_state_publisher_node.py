"""`robot_state_publisher` node (issue #4)."""
from ball_balance.nodes.pending import exit_not_implemented


def main(args=None):
    exit_not_implemented("robot_state_publisher", 4)
