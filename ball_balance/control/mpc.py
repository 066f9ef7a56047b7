"""Per-axis linear MPC on the discrete double integrator (docs/design.md section 6, step 4).

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
q, l, u and solves warm-started from its previous solution. OSQP also handles
infeasible-looking steps gracefully, and reports a status we check: anything but "solved"
falls back to the clipped, shifted previous plan and is counted.

Per tick, everything that does not depend on the measurement is precomputed: q of both axes
is one matrix product into a preallocated vector, the bounds are rescaled only when the gain
ratio or offset changes, and the solver's extension object is called directly. Most ticks
need no solver at all: the unconstrained optimum -H^-1 q (one more product) is checked
against every constraint, and when it meets them it is the QP's exact solution; OSQP runs
only when a constraint is active (a release far off centre, a push). About 11 us per tick
here without OSQP, 20 us with it (benchmarks/mpc_solve_bench.py).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.linalg
import scipy.sparse as sp

_OSQP_SOLVED = osqp.SolverStatus.OSQP_SOLVED


@dataclass(frozen=True)
class MpcConfig:
    dt_s: float = 0.02                 # model step = control period
    horizon: int = 25                  # N
    q_pos: float = 150.0               # weight on position error [1/m^2]
    q_vel: float = 6.0                 # weight on velocity error [1/(m/s)^2] (6 with 60 Hz: the push tail)
    r_u: float = 1.0                   # weight on (u - u_ff) [1/rad^2]
    r_du: float = 600.0                # weight on (u_k - u_{k-1}) [1/rad^2]
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
        F = 2.0 * S_u.T @ Q_bar                           # (N, 2N): q = F (S_x x0 - r) + ...
        self.n = n
        # q of both axes in one product: q (2, N) rows = axes = Z G, with Z = [p0, v0, ref_p', ref_v',
        # ref_a'] (2, 2 + 3N) filled in place each tick and G (2 + 3N, N) fixed: F S_x for the state,
        # -F's position and velocity columns for the reference, 2 R / k_g for the feed-forward
        # (-2 R u_ff with u_ff = -a / k_g). The input-difference term -2 R_d D' e1 v_prev touches
        # the first step only (D' e1 = e1): two scalars, set after the product.
        self._G = np.ascontiguousarray(np.vstack([(F @ S_x).T, -F[:, 0::2].T, -F[:, 1::2].T,
                                                  2.0 * cfg.r_u / cfg.k_g * np.eye(n)]))
        self._Z = np.zeros((2, 2 + 3 * n))
        self._prev_weight = 2.0 * cfg.r_du
        # Stacked two-axis problem: variables [U_x; U_y]; constraints [I; D] per axis.
        H2 = sp.block_diag([sp.csc_matrix(np.triu(H))] * 2, format="csc")
        A_axis = sp.vstack([sp.eye(n), sp.csc_matrix(D)])
        A2 = sp.block_diag([A_axis, A_axis], format="csc")
        # unconstrained optimum U = -H^-1 q (rows = axes) and its constraint rows [U, D U]
        self._free_gain = -np.linalg.inv(H).T
        self._rows_of = np.ascontiguousarray(A_axis.toarray().T)  # (N, 2N)
        self._free = np.zeros((2, n))
        self._free_rows = np.zeros((2, 2 * n))
        self._du = cfg.du_max_rad_s * dt
        one_axis_l = np.concatenate([np.full(n, -cfg.u_max_rad), np.full(n, -self._du)])
        self._l0 = np.concatenate([one_axis_l, one_axis_l])
        self._u0 = -self._l0
        self._l, self._u = self._l0.copy(), self._u0.copy()
        self._bounds_for = (1.0, 0.0, 0.0)  # (gain ratio, offsets) _l and _u were scaled for
        self._q = np.zeros(2 * n)
        self._q_rows = self._q.reshape(2, n)  # a view: the product writes q in place
        self._solver = osqp.OSQP()
        self._solver.setup(H2, self._q, A2, self._l, self._u, verbose=False, warm_starting=True,
                           polishing=False, eps_abs=cfg.eps, eps_rel=cfg.eps,
                           max_iter=cfg.max_iter, check_termination=5)
        # The osqp module's update() and solve() cost ~10 us of Python per tick (bounds clamped to
        # its infinity, a derivative cache, a namespace of every info field): the extension object
        # underneath takes the same vectors directly (our bounds are finite). Public API otherwise.
        core = getattr(self._solver, "_solver", None)
        self._core = core if all(hasattr(core, a) for a in ("update_data_vec", "solve", "info", "solution")) \
            else None
        self._plan = np.zeros(2 * n)
        self.failures = 0          # solves that were not "solved" (fallback used)
        self.unconstrained = 0     # ticks whose unconstrained optimum met the constraints
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
        n = self.n
        s_gain = float(gain_ratio)
        offset_x, offset_y = float(offset_rad[0]), float(offset_rad[1])
        u_prev_x, u_prev_y = float(u_prev[0]), float(u_prev[1])
        v_prev_x, v_prev_y = s_gain * u_prev_x - offset_x, s_gain * u_prev_y - offset_y
        Z = self._Z
        Z[:, 0] = x0
        Z[:, 1] = v0
        Z[:, 2:2 + n] = ref_p.T
        Z[:, 2 + n:2 + 2 * n] = ref_v.T
        Z[:, 2 + 2 * n:] = ref_a.T
        np.matmul(Z, self._G, out=self._q_rows)
        q = self._q
        q[0] -= self._prev_weight * v_prev_x
        q[n] -= self._prev_weight * v_prev_y
        # bounds: scaled tilt and rate limits, shifted by the offset on the tilt rows (rescaled only
        # when the gain ratio or the offset changed); the first rate row of each axis is
        # |v_0 - v_prev| <= s du
        lower, upper = self._l, self._u
        if self._bounds_for != (s_gain, offset_x, offset_y):
            self._bounds_for = (s_gain, offset_x, offset_y)
            np.multiply(self._l0, s_gain, out=lower)
            np.multiply(self._u0, s_gain, out=upper)
            lower[:n] -= offset_x
            upper[:n] -= offset_x
            lower[2 * n:3 * n] -= offset_y
            upper[2 * n:3 * n] -= offset_y
        rate = s_gain * self._du
        lower[n], upper[n] = v_prev_x - rate, v_prev_x + rate
        lower[3 * n], upper[3 * n] = v_prev_y - rate, v_prev_y + rate
        # the unconstrained optimum, when it meets every constraint, is the QP's solution
        free, free_rows = self._free, self._free_rows
        np.matmul(self._q_rows, self._free_gain, out=free)
        np.matmul(free, self._rows_of, out=free_rows)
        core = self._core
        if not ((free_rows < lower.reshape(2, -1)).any() or (free_rows > upper.reshape(2, -1)).any()):
            solved, x = True, free.reshape(-1)
            self.last_status = "solved"
            self.unconstrained += 1
        elif core is not None:
            core.update_data_vec(q=q, l=lower, u=upper)
            core.solve()
            solved = core.info.status_val == _OSQP_SOLVED
            self.last_status = core.info.status
            x = core.solution.x
        else:
            self._solver.update(q=q, l=lower, u=upper)
            result = self._solver.solve(raise_error=False)
            solved = result.info.status == "solved"
            self.last_status = result.info.status
            x = result.x
        if solved and math.isfinite(x.sum()):
            self._plan = np.array(x, dtype=float)
        else:
            self.failures += 1
            plan = self._plan  # the previous plan, shifted by one step
            self._plan = np.concatenate([plan[1:n], plan[n - 1:n], plan[n + 1:], plan[-1:]])
        u_max, du = self.cfg.u_max_rad, self._du
        # the first move must respect both limits whatever the solver returned
        u_x = (self._plan[0] + offset_x) / s_gain
        u_y = (self._plan[n] + offset_y) / s_gain
        u_x = min(max(min(max(u_x, u_prev_x - du), u_prev_x + du), -u_max), u_max)
        u_y = min(max(min(max(u_y, u_prev_y - du), u_prev_y + du), -u_max), u_max)
        self.last_solve_s = time.perf_counter() - t_start
        return float(u_x), float(u_y)

    def first_move_gains(self):
        """The unconstrained optimum's first move as a linear law, for batched use (the policy's
        training plant): v_0 = Z g + c v_prev per axis, with Z = [p0, v0, ref_p (N), ref_v (N),
        ref_a (N)] as `solve` fills it and v_prev the previous tilt, in the model's tilt.
        Returns (g (2 + 3N,), c)."""
        first = self._free_gain[:, 0]
        return self._G @ first, -self._prev_weight * float(first[0])

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
