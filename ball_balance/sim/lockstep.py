"""Lock-step with the control chain: simulated time waits for the answer to each camera frame.

With `pacing: lockstep` the simulation advances one manager period per cycle, but the camera
chain (render, tracker, controller) runs in other processes at whatever speed the machine
allows. Left alone, a slow renderer makes the chain's latency grow in simulated time, and the
same controller balances worse on a slower machine. `FrameAnswerGate` closes that gap: the
simulation does not capture the next frame, and so does not move more than one camera period
past a frame, until the answer to that frame has come back:

1. the loop captures frame k at simulated time t_k (`frame_captured(t_k)`);
2. a /ball_state stamped t_k arrives (the tracker's estimate from that frame: `on_state`);
3. a /plate_cmd arrives after it (the controller's step on that state: `on_command`).

The latency budget is therefore one camera period of simulated time, whatever the machine; a
faster chain answers sooner and the simulation does not wait at all.

A controller hosted in the simulation's own process (BallBalanceController in the controller
manager) steps on the manager's time grid, which does not move while the simulation waits,
and a controller node stepping on its own timer (the policy node) steps at its next tick of
simulated time, which the waiting simulation would never reach: for them the state's
arrival is the answer (`answer_on_state`), and their step follows within one control period
of simulated time.

Waiting starts with the first answer seen, so a graph with no tracker or no controller runs
free. A frame left unanswered for `timeout_wall_s` of wall-clock time (a lost message, a dead
node) is given up: it is counted, and waiting resumes with the next answer.

Threads: the loop calls `frame_captured`, `must_wait` and reads the counts; the executor calls
`on_state` and `on_command`. One lock guards the few fields (held for microseconds).
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Callable, Deque, Optional

STAMP_TOLERANCE_S = 1e-6      # header stamps are whole nanoseconds: a frame's time survives as one
# a frame unanswered this long is lost, not slow; well below the controllers' dead-peer timeout
# in simulation (joint_states_timeout_s 5 s in scripts/sim_balance.sh), which also watches
# /clock progress
ANSWER_TIMEOUT_WALL_S = 2.0
UNANSWERED_KEPT = 64          # frames remembered while running free (about 1 s at 60 Hz)


class FrameAnswerGate:
    def __init__(self, timeout_wall_s: float = ANSWER_TIMEOUT_WALL_S,
                 wall_clock: Callable[[], float] = time.monotonic):
        self.timeout_wall_s = timeout_wall_s
        self._wall = wall_clock
        self._lock = threading.Lock()
        # capture times of the frames not answered yet, oldest first: while the simulation runs
        # free (before the first answer, after a give-up) a slow chain answers an older frame
        # than the newest, and that answer must count, or waiting would never start
        self._unanswered: Deque[float] = deque(maxlen=UNANSWERED_KEPT)
        self._state_seen_s: Optional[float] = None   # the newest of them whose /ball_state arrived
        self._captured_wall_s = 0.0                  # when the newest was captured
        self._answers_coming = False                 # an answer was seen since the last give-up
        self.frames_answered = 0
        self.frames_given_up = 0
        self.wait_wall_s = 0.0                       # wall time spent waiting (for the real-time factor)
        self._wait_started_wall_s: Optional[float] = None
        self._answer_on_state = False

    @property
    def answer_on_state(self) -> bool:
        """Whether a frame's /ball_state is its answer, not the /plate_cmd after it: the
        controller is in this process, or steps on its own timer (see above)."""
        return self._answer_on_state

    @answer_on_state.setter
    def answer_on_state(self, value: bool) -> None:
        with self._lock:
            self._answer_on_state = bool(value)
            if self._answer_on_state and self._state_seen_s is not None:
                self._answered()      # a state already in answers its frame now

    def frame_captured(self, time_s: float) -> None:
        """(loop) Frame captured at simulated time `time_s`: its answer is awaited from now."""
        with self._lock:
            self._unanswered.append(time_s)
            self._captured_wall_s = self._wall()

    def on_state(self, stamp_s: float) -> None:
        """(executor) A /ball_state stamped `stamp_s` arrived."""
        with self._lock:
            if any(abs(stamp_s - t) <= STAMP_TOLERANCE_S for t in self._unanswered):
                self._state_seen_s = stamp_s
                if self._answer_on_state:
                    self._answered()

    def on_command(self) -> None:
        """(executor) A /plate_cmd arrived: the answer, when an unanswered frame's state came first."""
        with self._lock:
            if self._state_seen_s is not None:
                self._answered()

    def _answered(self) -> None:
        """The frame whose state was seen, and every older one, are answered."""
        while self._unanswered and self._unanswered[0] <= self._state_seen_s + STAMP_TOLERANCE_S:
            self._unanswered.popleft()
        self._state_seen_s = None
        self._answers_coming = True
        self.frames_answered += 1

    def must_wait(self) -> bool:
        """(loop) True while the newest frame is still unanswered (and answers are coming)."""
        with self._lock:
            now = self._wall()
            waiting = bool(self._unanswered) and self._answers_coming
            if waiting and now - self._captured_wall_s > self.timeout_wall_s:
                self.frames_given_up += 1
                self._unanswered.clear()
                self._state_seen_s, self._answers_coming, waiting = None, False, False
            if waiting and self._wait_started_wall_s is None:
                self._wait_started_wall_s = now
            elif not waiting and self._wait_started_wall_s is not None:
                self.wait_wall_s += now - self._wait_started_wall_s
                self._wait_started_wall_s = None
            return waiting


REPORT_PERIOD_S = 10.0   # wall-clock seconds between two pace lines


class PaceReport:
    """The pace line the simulation logs: how fast simulated time runs and why.

    The camera's rate and resolution are never lowered to suit the machine, since they shape
    what the controllers see; a machine too slow for them gets slower simulated time instead,
    and the first line says so with the render time measured."""

    def __init__(self, answers: FrameAnswerGate, camera, world, frame_period_s: float):
        self.answers, self.camera, self.world = answers, camera, world
        self.frame_period_s = frame_period_s
        self._last = None   # (wall s, sim s, wait s, given up)
        self._explained = False

    def summary(self) -> str:
        """The line for the end of a run: how many frames were answered and given up."""
        return (f"lock-step at t = {self.world.time_s:.1f} s: {self.answers.frames_answered} frame(s) answered, "
                f"{self.answers.frames_given_up} given up")

    def line(self, wall_s: float) -> str:
        sim_s, wait_s, given_up = self.world.time_s, self.answers.wait_wall_s, self.answers.frames_given_up
        last, self._last = self._last, (wall_s, sim_s, wait_s, given_up)
        if last is None or wall_s <= last[0] or sim_s <= last[1]:
            return ""   # the first call, or paused
        span_s = wall_s - last[0]
        factor = (sim_s - last[1]) / span_s
        waited = min(1.0, (wait_s - last[2]) / span_s)
        render_ms = 1e3 * self.camera.last_render_s if self.camera is not None else 0.0
        text = (f"simulated time at {factor:.2f}x real time, t = {sim_s:.1f} s (lock-step: {100 * waited:.0f} % of "
                f"the wall time waiting for the camera chain's answers")
        if render_ms > 0.0:
            text += f"; a frame renders in {render_ms:.1f} ms"
        text += ")"
        if given_up > last[3]:
            text += f"; {given_up - last[3]} frame(s) never answered within {self.answers.timeout_wall_s:g} s"
        if not self._explained and waited > 0.05:
            self._explained = True
            text += (f". This machine answers a frame more slowly than the camera's {1e3 * self.frame_period_s:.1f} "
                     "ms frame period: simulated time slows down to keep the camera's rate, resolution and latency "
                     "budget, so the outcome does not depend on the machine")
        return text
