"""Per-axis linear MPC on the discrete double integrator (docs/design.md section 6, step 2).

Model per plate axis, state x = [p, v] ([m], [m/s]), input u (tilt [rad]), zero-order hold
over dt:
    x_{k+1} = A x_k + B u_k,   A = [[1, dt], [0, 1]],   B = -k g [dt^2 / 2, dt]

Cost over the horizon N (condensed: the inputs U = [u_0 .. u_{N-1}] are the only unknowns,
X = S_x x_0 + S_u U):
    J = sum_k (x_k - r_k)' Q (x_k - r_k)  (+ terminal P_N from the Riccati equation)
      + R sum_k (u_k - u_ff,k)^2  +  R_d sum_k (u_k - u_{k-1})^2
with r_k the previewed reference (position and velocity) and u_ff,k = -a_ref,k / (k g) its
acceleration feed-forward. Constraints: |u_k| <= u_max, |u_k - u_{k-1}| <= du_max (u_{-1} is
the previous command).

Solver: OSQP (osqp 1.1.3, ADMM). Both axes are stacked block-diagonally into ONE sparse QP
of 2N variables set up once: the Hessian and constraint matrix never change (same model,
same weights), so OSQP factors its KKT system once and each tick only updates the vectors
q, l, u and solves warm-started from the previous solution (shifted). That is what keeps a
tick inside the 200 us budget without writing our own active-set code; OSQP also handles
infeasible-looking steps gracefully, and reports a status we check: anything but "solved"
falls back to the clipped, shifted previous plan and is counted.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.linalg
import scipy.sparse as sp


@dataclass(frozen=True)
class MpcConfig:
    dt_s: float = 0.02                 # model step = control period
    horizon: int = 25                  # N
    q_pos: float = 150.0               # weight on position error [1/m^2]
    q_vel: float = 10.0                # weight on velocity error [1/(m/s)^2]
    r_u: float = 1.0                   # weight on (u - u_ff) [1/rad^2]
    r_du: float = 400.0                # weight on (u_k - u_{k-1}) [1/rad^2]
    u_max_rad: float = 0.15            # tilt limit
    du_max_rad_s: float = 1.5          # tilt-rate limit
    k_g: float = 0.6 * 9.81            # rolling factor * gravity [m/s^2 per rad]
    eps: float = 1e-4                  # OSQP absolute/relative tolerance (1e-4 rad is plenty)
    max_iter: int = 200


class PlateMpc:
    """Two-axis MPC sharing one OSQP problem. `solve` returns (u_x, u_y) for this tick."""

    def __init__(self, cfg: MpcConfig):
        self.cfg = cfg
        n, dt, kg = cfg.horizon, cfg.dt_s, cfg.k_g
        self.A = np.array([[1.0, dt], [0.0, 1.0]])
        self.B = np.array([[-0.5 * kg * dt * dt], [-kg * dt]])
        Q = np.diag([cfg.q_pos, cfg.q_vel])
        # Terminal weight: infinite-horizon cost of the unconstrained LQR (stability).
        P_N = scipy.linalg.solve_discrete_are(self.A, self.B, Q, np.array([[cfg.r_u]]))
        # Prediction matrices: X = S_x x0 + S_u U, X stacked [x_1; ...; x_N] (2N)
        S_x = np.zeros((2 * n, 2))
        S_u = np.zeros((2 * n, n))
        A_pow = np.eye(2)
        for k in range(n):
            A_pow = self.A @ A_pow                       # A^(k+1)
            S_x[2 * k:2 * k + 2] = A_pow
            for j in range(k + 1):
                S_u[2 * k:2 * k + 2, j] = (np.linalg.matrix_power(self.A, k - j) @ self.B)[:, 0]
        Q_bar = scipy.linalg.block_diag(*([Q] * (n - 1) + [P_N]))
        # D U - e1 u_prev = the input differences
        D = np.eye(n) - np.eye(n, k=-1)
        # 1/2 U' H U + q' U with H, and q = F_x (S_x x0 - R_vec) - 2 R u_ff - 2 R_d D' e1 u_prev
        H = 2.0 * (S_u.T @ Q_bar @ S_u + cfg.r_u * np.eye(n) + cfg.r_du * D.T @ D)
        self._F = 2.0 * S_u.T @ Q_bar                     # (N, 2N)
        self._S_x = S_x
        self._e1_term = 2.0 * cfg.r_du * D.T[:, 0]        # times u_prev
        self.n = n
        # Stacked two-axis problem: variables [U_x; U_y]; constraints [I; D] per axis.
        H2 = sp.block_diag([sp.csc_matrix(np.triu(H))] * 2, format="csc")
        A_axis = sp.vstack([sp.eye(n), sp.csc_matrix(D)])
        A2 = sp.block_diag([A_axis, A_axis], format="csc")
        du = cfg.du_max_rad_s * dt
        one_axis_l = np.concatenate([np.full(n, -cfg.u_max_rad), np.full(n, -du)])
        self._l0 = np.concatenate([one_axis_l, one_axis_l])
        self._u0 = -self._l0
        self._l, self._u = self._l0.copy(), self._u0.copy()
        self._q = np.zeros(2 * n)
        self._solver = osqp.OSQP()
        self._solver.setup(H2, self._q, A2, self._l, self._u, verbose=False, warm_starting=True,
                           polishing=False, eps_abs=cfg.eps, eps_rel=cfg.eps,
                           max_iter=cfg.max_iter, check_termination=5)
        self._plan = np.zeros(2 * n)
        self.failures = 0          # solves that were not "solved" (fallback used)
        self.last_solve_s = 0.0    # wall time of the last solve() (vector updates + OSQP)
        self.last_status = ""

    def reset(self) -> None:
        self._plan[:] = 0.0
        self._solver.warm_start(x=self._plan, y=np.zeros(4 * self.n))

    def solve(self, x0: np.ndarray, v0: np.ndarray, ref_p: np.ndarray, ref_v: np.ndarray,
              ref_a: np.ndarray, u_prev: np.ndarray, gain_ratio: float = 1.0, offset_rad=(0.0, 0.0)):
        """One MPC tick.

        x0, v0: (2,) current (latency-compensated) ball position [m] and velocity [m/s].
        ref_p, ref_v, ref_a: (N, 2) previewed reference at steps 1..N.
        u_prev: (2,) previous command [rad]. Returns (u_x, u_y) [rad].
        gain_ratio s = k_g (estimated) / k_g (model) and offset_rad o = d / k_g (model), from an
        estimate of the plant x'' = -k_g u + d (control/estimation.py): the QP plans in the
        model's tilt v = s u - o, which the plant turns into the model's acceleration, so only
        the bounds change (|u| <= u_max becomes -s u_max - o <= v <= s u_max - o, the rate limit
        s du_max) and the factored problem is kept.
        """
        t_start = time.perf_counter()
        cfg, n = self.cfg, self.n
        s_gain = float(gain_ratio)
        offset = np.asarray(offset_rad, dtype=float)
        u_prev = np.asarray(u_prev, dtype=float)
        v_prev = s_gain * u_prev - offset
        # both axes at once: columns are axes. c = S_x x0 - r  (2N x 2), r stacked [p_k, v_k]
        X0 = np.array([x0, v0], dtype=float)                      # (2, 2): rows p, v
        R = np.empty((2 * n, 2))
        R[0::2] = ref_p
        R[1::2] = ref_v
        C = self._S_x @ X0 - R
        U_ff = -ref_a / cfg.k_g                                    # (N, 2)
        Q = self._F @ C - 2.0 * cfg.r_u * U_ff - np.outer(self._e1_term, v_prev)
        self._q[:n], self._q[n:] = Q[:, 0], Q[:, 1]
        # bounds: scaled tilt and rate limits, shifted by the offset on the tilt rows; the
        # first rate row of each axis is |v_0 - v_prev| <= s du
        lower, upper = self._l, self._u
        for axis in range(2):
            tilt_rows = slice(axis * 2 * n, axis * 2 * n + n)
            rate_rows = slice(axis * 2 * n + n, (axis + 1) * 2 * n)
            lower[tilt_rows] = s_gain * self._l0[tilt_rows] - offset[axis]
            upper[tilt_rows] = s_gain * self._u0[tilt_rows] - offset[axis]
            lower[rate_rows] = s_gain * self._l0[rate_rows]
            upper[rate_rows] = s_gain * self._u0[rate_rows]
            row = axis * 2 * n + n
            lower[row] += v_prev[axis]
            upper[row] += v_prev[axis]
        self._solver.update(q=self._q, l=lower, u=upper)
        # OSQP warm-starts from its previous primal/dual solution (warm_starting=True)
        shifted = np.concatenate([self._plan[1:n], self._plan[n - 1:n], self._plan[n + 1:], self._plan[-1:]])
        result = self._solver.solve(raise_error=False)
        self.last_status = result.info.status
        if result.info.status == "solved" and np.all(np.isfinite(result.x)):
            self._plan = np.asarray(result.x, dtype=float)
        else:
            self.failures += 1
            self._plan = shifted
        du = cfg.du_max_rad_s * cfg.dt_s
        u = (np.array([self._plan[0], self._plan[n]]) + offset) / s_gain
        # the first move must respect both limits whatever the solver returned
        u = np.clip(u, u_prev - du, u_prev + du)
        u = np.clip(u, -cfg.u_max_rad, cfg.u_max_rad)
        self.last_solve_s = time.perf_counter() - t_start
        return float(u[0]), float(u[1])

    def plan(self) -> np.ndarray:
        """The current plan, shape (N, 2) [rad]."""
        return np.stack([self._plan[:self.n], self._plan[self.n:]], axis=1)


def preview(reference, t_s: float, dt_s: float, horizon: int):
    """Reference at t_s + k dt, k = 1..horizon: arrays (N, 2) of p, v, a."""
    samples = [reference.sample(t_s + k * dt_s) for k in range(1, horizon + 1)]
    return (np.array([s.p for s in samples]), np.array([s.v for s in samples]),
            np.array([s.a for s in samples]))


def kg_default() -> float:
    from ball_balance.plate_geometry import GRAVITY_M_S2, ROLLING_FACTOR_SHELL

    return ROLLING_FACTOR_SHELL * GRAVITY_M_S2


assert math.isclose(MpcConfig().k_g, kg_default())
