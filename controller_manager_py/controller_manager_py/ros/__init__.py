"""ROS room: the controller manager's node, services, statistics/introspection publishers."""
