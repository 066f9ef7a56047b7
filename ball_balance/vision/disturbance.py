"""The disturbance state's change test and jump fits (vision/kalman.py BallKalman), written
once for a batch of filters (BatchBallKalman): the tracker's BallKalman is a batch of one,
the training plant's filter a batch of balls.

A change of d (a force that starts, turns or ends) shows as innovations that keep one sign.
`ChangeTest` keeps each filter's last DISTURBANCE_CHANGE_WINDOW_S of frames and tests their
whitened sum; on a change, `estimate_change` sizes it from the window (a generalised
likelihood ratio over the onsets, `Jumps`) and `open_disturbance` widens the covariance by a
change of unknown size. After a push's detection `JumpTest` tells a push from a force;
after a change found, `ChangeReview` asks whether it was a push after all.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

# The running innovation consistency (1 when the model is right) at most this: the model agrees
# with the detections. Only then is a detection beyond maneuver_sigma a push. The change test of
# d runs on a track whose model has agreed since its last change of d: a model that agreed and
# now disagrees has seen something change, which is the test's to find, whatever the detection
# noise does to the consistency meanwhile; a model that has not agreed since a change is seeing
# its own error (a delay or a gain still being learned), and the constant-velocity filter's
# velocity, or d fitted to that error window after window, would pass it on to the controller
MODEL_AGREED_NIS = 1.0
# the running consistency starts at 1 with a track; after this many of its time constants its
# start weighs 5 % and it describes the detections
CONSISTENCY_SETTLE_TIME_CONSTANTS = 3.0
DISTURBANCE_STD_M_S2 = 0.3   # 1-sigma of a change of d: a force up to about 3 degrees of tilt
# A change of d (a force that starts, turns or ends) shows as innovations that keep one sign:
# their whitened sum over DISTURBANCE_CHANGE_WINDOW_S, squared and over its frames, is
# chi-square with 2 degrees of freedom while the model holds; beyond DISTURBANCE_CHANGE_CHI2
# (a 0.1 % false alarm per test) d has changed by an unknown amount (1-sigma
# DISTURBANCE_STD_M_S2) about half a window ago, and the filter's covariance says so. d starts
# at 0, known: a plate off level from the start is found as such a change, once the gain is
# learned, instead of being learned together with a gain that is still wrong
DISTURBANCE_CHANGE_WINDOW_S = 0.3
DISTURBANCE_CHANGE_CHI2 = 13.815510557964274
# The window that passes the test is the one whose noise happened to lean the change's way:
# sized from it alone, a 1-degree step reads as 1.6 times its size on average (0.4-2.8 over
# seeds, test/unit/vision/test_kalman.py). So the change is sized this long after the test
# passes, from the window and the frames since, which the test did not select (1.2 times).
DISTURBANCE_CHANGE_SIZING_DELAY_S = 0.1


@dataclass
class ChangeFrame:
    """A detection in the change test's window: what the test and the change's estimate need."""
    t: float                     # stamp [s]
    whitened: np.ndarray         # the innovation whitened by its covariance
    agreed: bool                 # the model had agreed since the last change of d, before it
    innovation: np.ndarray       # z - H x of the prediction [m]
    S: np.ndarray                # its covariance
    transition: np.ndarray       # the product of the F's since the previous update
    K: Optional[np.ndarray] = None   # the update's gain, once made


def consistency_settle_s(time_constant_s: float) -> float:
    """How old a track must be before its running consistency (time constant
    `model_mismatch_time_constant_s`) describes the detections rather than its start value."""
    return CONSISTENCY_SETTLE_TIME_CONSTANTS * time_constant_s


def state_pair(n: int, first: int) -> np.ndarray:
    """The columns (n, 2) that pick the states first and first + 1 (an x and y pair)."""
    columns = np.zeros((n, 2))
    columns[first, 0] = columns[first + 1, 1] = 1.0
    return columns


def disturbance_rows(d_index: int) -> np.ndarray:
    """The state indices (x, vx, d_x) and (y, vy, d_y) of a filter whose d starts at d_index."""
    return np.array([[0, 2, d_index], [1, 3, d_index + 1]])


def disturbance_jerk(q_d, dt) -> np.ndarray:
    """The process noise (..., 3, 3) that a random walk of d with jerk density q_d adds over dt
    to (x, vx, d_x) (likewise y); q_d and dt scalars, or one value per filter of a batch."""
    q_d, dt = np.asarray(q_d, dtype=float)[..., None, None], np.asarray(dt, dtype=float)[..., None, None]
    return q_d * _JERK_COEFFICIENTS * dt ** _JERK_POWERS


_JERK_COEFFICIENTS = np.array([[1 / 20, 1 / 8, 1 / 6], [1 / 8, 1 / 3, 1 / 2], [1 / 6, 1 / 2, 1.0]])
_JERK_POWERS = np.array([[5, 4, 3], [4, 3, 2], [3, 2, 1]])


def open_disturbance(P: np.ndarray, T, d_index: int) -> None:
    """Widen the covariance P (n, n), or a batch of them (b, n, n) with T (b,), by that of a
    change of d of 1-sigma DISTURBANCE_STD_M_S2 that happened T ago, with the velocity and
    position it has moved since."""
    T = np.asarray(T, dtype=float)[..., None]
    J = np.concatenate([T * T / 2.0, T, np.ones_like(T)], axis=-1)        # (..., 3)
    rows = disturbance_rows(d_index)
    P[..., rows[:, :, None], rows[:, None, :]] += DISTURBANCE_STD_M_S2 ** 2 * (J[..., None, :, None]
                                                                              * J[..., None, None, :])


def estimate_change(frames, d_index: int) -> Optional[np.ndarray]:
    """The state correction for the change of d that a change test's window shows, or None.
    `frames` are the window's ChangeFrame in order, the current frame last (its innovation is
    not used; its transition takes the correction to its prediction). For each frame the
    change may have happened in the prediction into, a jump of d is fitted to the
    innovations since (Jumps); the onset of the largest evidence under the change's prior
    N(0, DISTURBANCE_STD_M_S2^2 I) is taken (generalised likelihood ratio, Willsky and Jones),
    and the correction is that jump's posterior mean. The caller opens the covariance as for a
    change of unknown size (open_disturbance), so the frames that follow still move d."""
    if len(frames) < 2:
        return None
    jumps = Jumps.fitted(frames[:-1], [frame.transition for frame in frames],
                         state_pair(frames[0].transition.shape[0], d_index))
    best = int(np.argmax(jumps.evidence(DISTURBANCE_STD_M_S2)))
    return jumps.posterior(best, DISTURBANCE_STD_M_S2)[0]


class Jumps:
    """Explanations of a filter's innovations by a jump of the states that `columns` (n, 2)
    picks, one per onset: a jump in the prediction into the frame at each onset, fitted to the
    innovations since (a generalised likelihood ratio, kept up frame by frame). Per onset, with
    G = H (B - A) the jump's signature in the innovation, B its effect on the state had the
    filter not reacted and A what the filter's updates took up of it:
    information = sum G^T S^-1 G and score = sum G^T S^-1 y over the frames since."""

    def __init__(self, columns: np.ndarray):
        self.columns = columns
        n = columns.shape[0]
        self.onset_s = np.zeros(0)
        self.B, self.A = np.zeros((0, n, 2)), np.zeros((0, n, 2))
        self.information, self.score = np.zeros((0, 2, 2)), np.zeros((0, 2))
        self._signature = np.zeros((0, 2, 2))

    @classmethod
    def fitted(cls, frames, transitions, columns: np.ndarray) -> Jumps:
        """The jumps at each of `frames` (ChangeFrame, each with its update's gain), fitted to
        the frames since; transitions[j] is the prediction into frame j, one more than the
        frames: the last takes the jumps to the frame after them."""
        jumps = cls(columns)
        for j, frame in enumerate(frames):
            jumps.add_onset(frame.t, transitions[j])
            jumps.add(frame.innovation, frame.S)
            jumps.take_up(frame.K)
            jumps.predict(transitions[j + 1])
        return jumps

    def add_onset(self, t: float, transition: np.ndarray) -> None:
        """A jump in the prediction into the frame at t, whose transition that is."""
        self.onset_s = np.append(self.onset_s, t)
        self.B = np.concatenate([self.B, (transition @ self.columns)[None]])
        self.A = np.concatenate([self.A, np.zeros((1,) + self.A.shape[1:])])
        self.information = np.concatenate([self.information, np.zeros((1, 2, 2))])
        self.score = np.concatenate([self.score, np.zeros((1, 2))])

    def predict(self, F: np.ndarray) -> None:
        self.B, self.A = F @ self.B, F @ self.A

    def add(self, innovation: np.ndarray, S: np.ndarray) -> None:
        """A frame's innovation and its covariance, before the update."""
        G = (self.B - self.A)[:, :2]
        S_inv_G = np.linalg.solve(S, G)
        self.score += np.einsum("mij,i->mj", S_inv_G, innovation)
        self.information += np.einsum("mki,mkj->mij", G, S_inv_G)
        self._signature = G

    def take_up(self, K: np.ndarray) -> None:
        """The update's gain K (n, 2): how much of each jump the filter took up."""
        self.A = self.A + K @ self._signature

    def statistics(self) -> np.ndarray:
        """Per onset, twice the log-likelihood gained by the jump of the best size:
        score^T information^-1 score (0 while the frames cannot size it)."""
        out = np.zeros(len(self.onset_s))
        sized = np.linalg.det(self.information) > 0.0
        if sized.any():
            score = self.score[sized]
            solved = np.linalg.solve(self.information[sized], score[..., None])[..., 0]
            out[sized] = np.einsum("mi,mi->m", score, solved)
        return out

    def evidence(self, prior_std: float) -> np.ndarray:
        """Per onset, the log evidence of the jump against none under its prior
        N(0, prior_std^2 I), up to a constant."""
        information = self.information + np.eye(2) / prior_std ** 2
        fit = np.einsum("mi,mi->m", self.score, np.linalg.solve(information, self.score[..., None])[..., 0])
        return fit - np.log(np.linalg.det(information) * prior_std ** 4)

    def posterior(self, k: int, prior_std: float):
        """Jump k's effect on the state now, given the frames since its onset and its prior
        N(0, prior_std^2 I): the mean and the covariance to add to the filter's."""
        covariance = np.linalg.inv(self.information[k] + np.eye(2) / prior_std ** 2)
        effect = self.B[k] - self.A[k]
        return effect @ (covariance @ self.score[k]), effect @ covariance @ effect.T


class ChangeTest:
    """The change test per filter of a batch of `batch` (BallKalman's is a batch of one): each
    filter's window, a ring of its frames' stamps, whitened innovations, whether the model had
    agreed before them, innovations, their covariances, the transitions since the previous
    update and the updates' gains, `n` frames from `head`, doubled when a window would overflow
    it (a faster camera). A window is tested once it spans DISTURBANCE_CHANGE_WINDOW_S, if at
    its first frame the track's model had agreed with the detections since its last change of d
    (MODEL_AGREED_NIS) and the track was `settle_s` old (consistency_settle_s); otherwise a bias
    is the model's own error. A change found is sized DISTURBANCE_CHANGE_SIZING_DELAY_S later,
    from the window that found it and the frames since."""

    FIELDS = ("t", "whitened", "agreed", "innovation", "S", "transition", "K")

    def __init__(self, batch: int, dim: int, d_index: int, settle_s: float, capacity: int = 32):
        self.b, self.dim, self.cap = batch, dim, capacity
        self.d_index, self.settle_s = d_index, settle_s
        self.t = np.full((batch, capacity), np.nan)
        self.whitened = np.zeros((batch, capacity, 2))
        self.agreed = np.zeros((batch, capacity), bool)
        self.innovation = np.zeros((batch, capacity, 2))
        self.S = np.zeros((batch, capacity, 2, 2))
        self.transition = np.zeros((batch, capacity, dim, dim))
        self.K = np.zeros((batch, capacity, dim, 2))
        self.head = np.zeros(batch, int)
        self.n = np.zeros(batch, int)
        self.start = np.full(batch, np.nan)    # when the window began to fill (nan: not yet)
        self.sizing_at = np.full(batch, np.nan)   # when a change found is sized (nan: none found)

    def clear(self, mask=slice(None)) -> None:
        """Start the windows of `mask` (all by default) again."""
        self.n[mask] = 0
        self.start[mask] = np.nan
        self.sizing_at[mask] = np.nan

    def test(self, t: float, add, innovation, S, agreed, transition, track_start_s) -> np.ndarray:
        """The frame at t of the filters `add` (b,) joins their windows, before their update:
        innovation (b, 2) and its covariance S (b, 2, 2), whether the track's model had agreed
        with the detections since its last change of d (b,), the transition since the previous
        update (b, dim, dim); track_start_s (b,) when each track began. Returns the filters to
        `correct`: those whose window showed a change of d DISTURBANCE_CHANGE_SIZING_DELAY_S
        ago; for the others call `set_last_gain` after the update."""
        whitened = np.linalg.solve(np.linalg.cholesky(S), innovation[..., None])[..., 0]
        self._append(add, t, whitened, agreed, innovation, S, transition)
        found = ~np.isnan(self.sizing_at)
        # a change found keeps its window and the frames since until it is sized
        self._drop_older(add & ~found, t, DISTURBANCE_CHANGE_WINDOW_S)
        self.start = np.where(add & np.isnan(self.start), t, self.start)
        full = add & ~found & (t - self.start >= DISTURBANCE_CHANGE_WINDOW_S)
        tested = full & self._oldest("agreed") & self.settled(self._oldest("t"), track_start_s)
        if tested.any():
            total = self._sum_whitened()
            passed = tested & (np.einsum("bi,bi->b", total, total) / np.maximum(self.n, 1) > DISTURBANCE_CHANGE_CHI2)
            # less a nanosecond: a frame stamped the delay later, to rounding, sizes it
            self.sizing_at = np.where(passed, t + DISTURBANCE_CHANGE_SIZING_DELAY_S - 1e-9, self.sizing_at)
        return add & (t >= self.sizing_at)

    def settled(self, t, track_start_s) -> np.ndarray:
        """Whether tracks begun at track_start_s are `settle_s` old at t: their running
        consistency describes the detections rather than its start value."""
        return np.asarray(t) - np.asarray(track_start_s) >= self.settle_s

    def correct(self, i: int, t: float, x: np.ndarray, P: np.ndarray) -> None:
        """Filter i's window showed a change DISTURBANCE_CHANGE_SIZING_DELAY_S before t: correct
        its state x (n,) in place by the change that window and the frames since show
        (estimate_change) and widen its covariance P (n, n) by that of a change of 1-sigma
        DISTURBANCE_STD_M_S2 half their span ago (open_disturbance): d by
        it, the velocity by it times T, the position by it times T^2/2, all correlated, so the
        innovations that follow still move d, and not the velocity, by what the change was.
        The window starts again."""
        frames = self.frames(i)
        jump = estimate_change(frames, self.d_index)
        if jump is not None:
            x += jump
        open_disturbance(P, (t - frames[0].t) / 2.0, self.d_index)
        self.clear(i)

    def set_last_gain(self, mask, K) -> None:
        """The update's gain K (m, dim, 2) of the frames just added for the filters in mask."""
        i = np.flatnonzero(mask)
        self.K[i, (self.head[i] + self.n[i] - 1) % self.cap] = K

    def frames(self, i: int) -> list:
        """Filter i's window, its ChangeFrame oldest first."""
        at = (self.head[i] + np.arange(self.n[i])) % self.cap
        return [ChangeFrame(self.t[i, k], self.whitened[i, k], self.agreed[i, k], self.innovation[i, k], self.S[i, k],
                            self.transition[i, k], self.K[i, k]) for k in at]

    def _append(self, mask, t, whitened, agreed, innovation, S, transition) -> None:
        if (self.n[mask] >= self.cap).any():
            self._grow()
        i = np.flatnonzero(mask)
        at = (self.head[i] + self.n[i]) % self.cap
        self.t[i, at], self.whitened[i, at], self.agreed[i, at] = t, whitened[i], agreed[i]
        self.innovation[i, at], self.S[i, at], self.transition[i, at] = innovation[i], S[i], transition[i]
        self.n[i] += 1

    def _grow(self) -> None:
        order = (self.head[:, None] + np.arange(self.cap)) % self.cap     # oldest first
        rows = np.arange(self.b)[:, None]
        for name in self.FIELDS:
            old = getattr(self, name)[rows, order]
            setattr(self, name, np.concatenate([old, np.zeros_like(old)], axis=1))
        self.head[:] = 0
        self.cap *= 2

    def _drop_older(self, mask, t: float, span_s: float) -> None:
        """Drop the frames more than span_s older than t."""
        while True:
            old = mask & (self.n > 0) & (t - self._oldest("t") > span_s)
            if not old.any():
                return
            self.head = np.where(old, (self.head + 1) % self.cap, self.head)
            self.n -= old

    def _oldest(self, name: str) -> np.ndarray:
        return getattr(self, name)[np.arange(self.b), self.head]

    def _sum_whitened(self) -> np.ndarray:
        order = (self.head[:, None] + np.arange(self.cap)) % self.cap
        inside = np.arange(self.cap)[None, :] < self.n[:, None]
        return np.einsum("bk,bki->bi", inside, self.whitened[np.arange(self.b)[:, None], order])


class JumpTest:
    """After a push's detection (with the disturbance state and a known acceleration): was it a
    push, a jump of the ball's velocity, or a force that started or turned, a change of d? A
    reference filter (its state x, covariance P and measurement variance r, copied from the
    filter before the push) runs on with the model's own process noise, and for each onset from
    the change test's window on, each of the two jumps is fitted to its innovations
    (generalised likelihood ratio, as estimate_change). Both explanations have two free
    parameters and an onset, so their best fits compare directly: once twice the
    log-likelihood ratio between the best of each passes DISTURBANCE_CHANGE_CHI2 (the change
    test's bound) the test has decided. The filter (vision/kalman.py BatchBallKalman) predicts
    and updates the reference filter; this class keeps the fits. `taken`: what the filter took
    the jump for meanwhile (a push: its hold); the other decision replaces the filter by the
    reference filter with that jump's posterior, under its prior (DISTURBANCE_STD_M_S2 for a
    change of d, push_std for a velocity jump)."""

    taken = "push"

    def __init__(self, x: np.ndarray, P: np.ndarray, r: float, window, transition: np.ndarray, t: float,
                 d_index: int, push_std: float):
        self.x, self.P, self.r = x.copy(), P.copy(), r
        self.push_std = push_std
        n = x.shape[0]
        transitions = [frame.transition for frame in window] + [transition]
        self.forces = Jumps.fitted(window, transitions, state_pair(n, d_index))   # of d
        self.pushes = Jumps.fitted(window, transitions, state_pair(n, 2))         # of (vx, vy)
        self.fits = [self.forces, self.pushes]     # the fits kept up frame by frame
        self._add_onset(t, transition)

    def _add_onset(self, t: float, transition: np.ndarray) -> None:
        """The jumps in the prediction into the frame at t, whose transition that is."""
        for fit in self.fits:
            fit.add_onset(t, transition)

    def predict(self, t: float, F: np.ndarray) -> None:
        """After the reference filter's prediction F into the frame at t: the jumps so far move
        on, and either may happen in this prediction too."""
        for fit in self.fits:
            fit.predict(F)
        self._add_onset(t, F)

    def add(self, innovation: np.ndarray, S: np.ndarray) -> None:
        """The reference filter's innovation of a detection and its covariance, before its update."""
        for fit in self.fits:
            fit.add(innovation, S)

    def take_up(self, K: np.ndarray) -> Optional[str]:
        """The reference filter's update gain K for the detection just added: "force" or "push"
        once decided, else None."""
        for fit in self.fits:
            fit.take_up(K)
        return decision(self.log_ratio())

    def log_ratio(self) -> float:
        """Twice the log-likelihood ratio of the best force against the best push."""
        return self.forces.statistics().max() - self.pushes.statistics().max()

    def posterior(self, jump: str):
        """The best-fitting `jump`'s ("force": of d, "push": of the velocity) effect on the
        reference filter's state under its prior: the mean and the covariance to add
        (Jumps.posterior)."""
        jumps, prior_std = (self.forces, DISTURBANCE_STD_M_S2) if jump == "force" else (self.pushes, self.push_std)
        return jumps.posterior(int(np.argmax(jumps.statistics())), prior_std)


class ChangeReview(JumpTest):
    """After a change of d was found with a push's detection in the change test's window (one
    the detection noise did not let the push test confirm), or a jump test decided on one
    (`after`): was it a push after all? The
    change stands, in the filter, unless a push explains the frames better. The reference
    filter is the filter as it was, without the change, and the explanations are compared by
    their evidence (the jump's size integrated over its prior) since the window began:
    a change of d, the evidence of its best onset in the window (estimate_change's fit) and
    the likelihood of the frames since under the filter that took it; a push, the reference
    filter's likelihood and the evidence of its best onset (prior N(0, push_std^2 I)). Decided
    when one is ahead by DISTURBANCE_CHANGE_CHI2, or, by `until`, the change stands."""

    taken = "force"

    def __init__(self, x: np.ndarray, P: np.ndarray, r: float, window, transition: np.ndarray, t: float,
                 d_index: int, push_std: float, until: float):
        super().__init__(x, P, r, window, transition, t, d_index, push_std)
        self._review(until)

    @classmethod
    def after(cls, test: JumpTest, until: float) -> ChangeReview:
        """The review of a change of d `test` has just decided on: its reference filter, without
        the change, and its push fits run on; the change's side is its best fit so far."""
        review = cls.__new__(cls)
        review.x, review.P, review.r, review.push_std = test.x.copy(), test.P.copy(), test.r, test.push_std
        review.forces, review.pushes = test.forces, test.pushes
        review._review(until)
        return review

    def _review(self, until: float) -> None:
        """From the fits so far on: the change's side fixed at its best fit, the push's kept up."""
        self.until = until
        self.force_evidence = float(self.forces.evidence(DISTURBANCE_STD_M_S2).max())
        self.fits = [self.pushes]      # the change's side is the window's fit and the filter
        self.filter_log_ratio = 0.0    # twice the log-likelihood of the frames since: filter less reference

    def add_filtered(self, innovation: np.ndarray, S: np.ndarray) -> None:
        """The innovation of a detection and its covariance in the filter that took the change."""
        self.filter_log_ratio -= _log_likelihood_terms(innovation, S)

    def add(self, innovation: np.ndarray, S: np.ndarray) -> None:
        super().add(innovation, S)
        self.filter_log_ratio += _log_likelihood_terms(innovation, S)

    def log_ratio(self) -> float:
        """Twice the log evidence ratio of the change, as the filter took it, against a push."""
        push_evidence = float(self.pushes.evidence(self.push_std).max())
        return self.force_evidence + self.filter_log_ratio - push_evidence


def decision(log_ratio: float) -> Optional[str]:
    """"force" or "push" once twice the log-likelihood ratio of a force against a push is
    beyond DISTURBANCE_CHANGE_CHI2 either way, else None."""
    if log_ratio > DISTURBANCE_CHANGE_CHI2:
        return "force"
    if log_ratio < -DISTURBANCE_CHANGE_CHI2:
        return "push"
    return None


def _log_likelihood_terms(innovation: np.ndarray, S: np.ndarray) -> float:
    """y^T S^-1 y + log det S: minus twice a Gaussian innovation's log-likelihood, less a constant."""
    return float(innovation @ np.linalg.solve(S, innovation) + np.log(np.linalg.det(S)))
