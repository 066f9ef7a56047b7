import time

import numpy as np
from control_plant import K_G, DelayedPlant

from ball_balance.control.mpc import MpcConfig, PlateMpc, preview
from ball_balance.control.references import Circle, Stationary


def _run(mpc, plant, ref, seconds, dt=0.02):
    u = np.zeros(2)
    us = []
    for i in range(int(seconds / dt)):
        p, v, a = preview(ref, i * dt, dt, mpc.cfg.horizon)
        u = np.array(mpc.solve(plant.p, plant.v, p, v, a, u))
        us.append(u)
        plant.advance(u, dt)
    return np.array(us)


def test_sign_convention_positive_error_gives_positive_tilt():
    mpc = PlateMpc(MpcConfig(k_g=K_G))
    p, v, a = preview(Stationary(), 0.0, 0.02, 25)
    ux, uy = mpc.solve(np.array([0.05, -0.05]), np.zeros(2), p, v, a, np.zeros(2))
    assert ux > 0 and uy < 0


def test_tilt_and_rate_constraints_hold_for_a_large_error():
    cfg = MpcConfig(k_g=K_G, u_max_rad=0.08, du_max_rad_s=1.0)
    mpc = PlateMpc(cfg)
    us = _run(mpc, DelayedPlant(x0=(0.2, -0.2), v0=(0.3, 0.0)), Stationary(), 4.0)
    assert np.max(np.abs(us)) <= cfg.u_max_rad + 1e-9
    steps = np.diff(np.vstack([np.zeros(2), us]), axis=0)
    assert np.max(np.abs(steps)) <= cfg.du_max_rad_s * cfg.dt_s + 1e-9
    assert np.max(np.abs(us)) > 0.99 * cfg.u_max_rad  # the limit was actually active
    plan = mpc.plan()
    assert np.max(np.abs(plan)) <= cfg.u_max_rad + 1e-4


def test_settles_and_tracks_a_circle():
    mpc = PlateMpc(MpcConfig(k_g=K_G))
    plant = DelayedPlant(x0=(0.1, -0.1))
    _run(mpc, plant, Stationary(), 4.0)
    assert np.linalg.norm(plant.p) < 0.002
    ref = Circle(0.1, 10.0)
    _run(mpc, plant, ref, 10.0)
    assert np.linalg.norm(plant.p - ref.sample(10.0).p) < 0.003
    assert mpc.failures == 0


def test_solve_is_warm_started_and_reports_solved():
    mpc = PlateMpc(MpcConfig(k_g=K_G))
    p, v, a = preview(Circle(0.1, 10.0), 0.0, 0.02, 25)
    mpc.solve(np.zeros(2), np.zeros(2), p, v, a, np.zeros(2))
    t0 = time.perf_counter()
    mpc.solve(np.zeros(2), np.zeros(2), p, v, a, np.zeros(2))
    assert mpc.last_status == "solved"
    assert time.perf_counter() - t0 < 0.05  # sanity only; timing is measured in the benchmark
