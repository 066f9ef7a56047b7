"""Closed-loop benchmark (docs/design.md section 7): lock-stepped simulation, camera/tracker (or
the simulator's truth plus a noise model) and the control pipeline, episode by episode from
a seed, so results do not depend on machine load. No ROS import.

    from ball_balance.benchmark.episode import EpisodeSpec, run_episode
    result = run_episode(EpisodeSpec(controller="mpc", domain="standard", reference="circle", seed=3))
    result.metrics  # drop, rmse_m, settle_s, peak_tilt_rad, smoothness_rad_s, latency_s, ...
"""
