"""Operating the system: the robot manager's lifecycle bookkeeping, its watchdogs and the
plate's levelling path. Plain Python (no ROS import); the node is nodes/robot_manager_node.py."""
