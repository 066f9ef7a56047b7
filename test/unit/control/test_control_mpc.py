import time

import numpy as np
import pytest
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


def _unconstrained_plan(cfg, x0, v0, p, v, a, u_prev):
    """The cost of the module docstring minimised directly (one axis, least squares), for a
    check of the precomputed per-tick vector q independent of its derivation."""
    import scipy.linalg

    n, dt, kg = cfg.horizon, cfg.dt_s, cfg.k_g
    A = np.array([[1.0, dt], [0.0, 1.0]])
    B = np.array([[-0.5 * kg * dt * dt], [-kg * dt]])
    Q = np.diag([cfg.q_pos, cfg.q_vel])
    P_N = scipy.linalg.solve_discrete_are(A, B, Q, np.array([[cfg.r_u]]))
    rows, rhs = [], []
    for k in range(n):  # x_{k+1} = A^(k+1) x0 + sum_j A^(k-j) B u_j
        M = np.zeros((2, n))
        for j in range(k + 1):
            M[:, j] = (np.linalg.matrix_power(A, k - j) @ B)[:, 0]
        free = np.linalg.matrix_power(A, k + 1) @ np.array([x0, v0])
        W = scipy.linalg.sqrtm(P_N if k == n - 1 else Q).real
        rows.append(W @ M)
        rhs.append(W @ (np.array([p[k], v[k]]) - free))
    eye = np.eye(n)
    rows.append(np.sqrt(cfg.r_u) * eye)
    rhs.append(np.sqrt(cfg.r_u) * (-a / kg))
    D = eye - np.eye(n, k=-1)
    rows.append(np.sqrt(cfg.r_du) * D)
    rhs.append(np.sqrt(cfg.r_du) * np.concatenate([[u_prev], np.zeros(n - 1)]))
    return np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]


def test_first_move_is_the_cost_minimum_when_no_constraint_is_active():
    cfg = MpcConfig(k_g=K_G)
    mpc = PlateMpc(cfg)
    p, v, a = preview(Circle(0.02, 10.0), 0.3, cfg.dt_s, cfg.horizon)
    x0, v0, u_prev = np.array([0.004, -0.003]), np.array([0.01, 0.02]), np.array([0.002, -0.001])
    u = mpc.solve(x0, v0, p, v, a, u_prev)
    assert mpc.unconstrained == 1  # (solved without OSQP: exact)
    for axis in range(2):
        expected = _unconstrained_plan(cfg, x0[axis], v0[axis], p[:, axis], v[:, axis], a[:, axis], u_prev[axis])
        assert abs(expected).max() < 0.5 * cfg.u_max_rad  # (the constraints are inactive)
        assert u[axis] == pytest.approx(expected[0], abs=1e-9)


def test_solver_core_and_public_interface_agree():
    """The per-tick fast path (OSQP's extension object) and the osqp module's public API."""
    cfg = MpcConfig(k_g=K_G)
    fast, public = PlateMpc(cfg), PlateMpc(cfg)
    public._core = None
    u_fast = u_public = np.zeros(2)
    for i, (gain, offset) in enumerate([(1.0, (0.0, 0.0)), (1.2, (0.01, -0.02)), (0.8, (0.0, 0.03))] * 3):
        p, v, a = preview(Circle(0.1, 10.0), 0.02 * i, cfg.dt_s, cfg.horizon)
        x0 = np.array([0.15, -0.1])
        u_fast = np.array(fast.solve(x0, np.zeros(2), p, v, a, u_fast, gain_ratio=gain, offset_rad=offset))
        u_public = np.array(public.solve(x0, np.zeros(2), p, v, a, u_public, gain_ratio=gain, offset_rad=offset))
        assert np.allclose(u_fast, u_public, atol=1e-9)
        assert fast.last_status == public.last_status == "solved"
    assert fast.unconstrained < 9  # (OSQP ran in some ticks: a constraint was active)
