"""Standard controllers (ros2_controllers equivalents), registered in setup.py's entry points."""
