"""Ball-balance control math (no rclpy): references, PID, MPC, latency prediction, safety,
plate kinematics, and the pipeline that composes them (docs/design.md section 6).

Plant per plate axis (small angles): x'' = -k g u, with u_x the tilt about the plate y axis
and u_y the tilt about the plate x axis; positive u drives the ball toward negative x / y.
"""
