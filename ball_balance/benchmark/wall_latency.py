"""Camera-to-command latency: each frame's /ball_state paired with the /plate_cmd that answers
it, measured on the header stamps and, as a second figure, on the wall clock.

Pairing: the answer to a /ball_state is the first /plate_cmd written after it (DDS source
timestamps, written by the publishers: the order the graph wrote them in, whenever the
monitor read them). The stamps cannot pair them: a node on simulated time stamps its command
with the last /clock it saw, which may lie before the frame's capture.

  stamps      command stamp - the frame's stamp (its capture time): simulated time in the
              simulated graph, where a slow machine slows simulated time down with the control
              chain (lock-step), so this is the latency the plant sees; wall-clock time with a
              real camera. The headline.
  wall clock  command written - capture, with the capture on the wall clock through the /clock
              samples: each says "simulated time t was reached at wall time w" (w: the DDS
              source timestamp, written by the simulation loop that also captures the frames),
              and the offset w - t is interpolated at the stamp; without /clock samples the
              stamps already are wall-clock times. What a user waits for; at a real-time factor
              of 0.2 it is five times the stamps' figure. The same pairing as
              benchmarks/latency_budget_bench.py's "capture -> command written" (which takes the
              capture time from the simulation's latency trace instead of the /clock map).

Plain Python, no ROS: the monitor (ball_balance/benchmark/live.py) and the benchmark feed it.
"""
from __future__ import annotations

import bisect
import math

import numpy as np


class CameraToCommand:
    def __init__(self) -> None:
        self._clock_sim_s: list[float] = []     # /clock: simulated time ...
        self._clock_offset_s: list[float] = []  # ... and (wall written - simulated), s
        self._states: list[tuple[float, float]] = []   # (frame stamp s, /ball_state written wall s)
        self._commands: list[tuple[float, float]] = []  # (command written wall s, its stamp s)

    def add_clock(self, sim_s: float, written_wall_s: float) -> None:
        """A /clock sample: simulated time sim_s, written at wall time written_wall_s."""
        if self._clock_sim_s and sim_s <= self._clock_sim_s[-1]:
            if sim_s < self._clock_sim_s[-1] - 1.0:        # the clock went back (a restart): start over
                self._clock_sim_s.clear()
                self._clock_offset_s.clear()
            else:
                return
        self._clock_sim_s.append(sim_s)
        self._clock_offset_s.append(written_wall_s - sim_s)

    def add_state(self, stamp_s: float, written_wall_s: float) -> None:
        """A /ball_state of the frame stamped stamp_s, written at wall time written_wall_s."""
        self._states.append((stamp_s, written_wall_s))

    def add_command(self, written_wall_s: float, stamp_s: float = math.nan) -> None:
        """A /plate_cmd written at wall time written_wall_s, stamped stamp_s."""
        self._commands.append((written_wall_s, stamp_s))

    def capture_wall_s(self, stamp_s: float) -> float:
        """A stamp on the wall clock: through the /clock samples when there are any, else as is."""
        if not self._clock_sim_s:
            return stamp_s
        return stamp_s + float(np.interp(stamp_s, self._clock_sim_s, self._clock_offset_s))

    def _answered(self, since_s: float, until_s: float):
        """(frame stamp, state written, answer written, answer stamp) per /ball_state stamped in
        [since_s, until_s] that a command was written after."""
        commands = sorted(self._commands)
        written = [w for w, _ in commands]
        for stamp_s, state_written_s in self._states:
            if since_s <= stamp_s <= until_s:
                i = bisect.bisect_right(written, state_written_s)
                if i < len(commands):
                    yield stamp_s, state_written_s, commands[i][0], commands[i][1]

    def latencies_s(self, since_s: float = -math.inf, until_s: float = math.inf) -> np.ndarray:
        """Wall clock: capture -> first command written after the frame's /ball_state, s, per state."""
        # no extrapolation past the last /clock sample read: slower than real time, the offset
        # grows by (1 - real-time factor) per simulated second, and a monitor that reads its
        # states ahead of its clock would put seconds of that into the latency
        last_clock_s = self._clock_sim_s[-1] if self._clock_sim_s else math.inf
        return np.array([written_s - self.capture_wall_s(stamp_s)
                         for stamp_s, _, written_s, _ in self._answered(since_s, min(until_s, last_clock_s))],
                        dtype=float)

    def stamp_latencies_s(self, since_s: float = -math.inf, until_s: float = math.inf) -> np.ndarray:
        """Header stamps: the answering command's stamp - the frame's stamp, s, per state."""
        return np.array([answer_stamp_s - stamp_s
                         for stamp_s, _, _, answer_stamp_s in self._answered(since_s, until_s)], dtype=float)

    def real_time_factor(self, since_s: float = -math.inf, until_s: float = math.inf) -> float:
        """Simulated seconds per wall second over the /clock samples in [since_s, until_s]
        (nan with fewer than two)."""
        sim = np.array(self._clock_sim_s)
        inside = (sim >= since_s) & (sim <= until_s)
        if np.count_nonzero(inside) < 2:
            return math.nan
        sim, wall = sim[inside], sim[inside] + np.array(self._clock_offset_s)[inside]
        return float((sim[-1] - sim[0]) / (wall[-1] - wall[0])) if wall[-1] > wall[0] else math.nan


def source_wall_s(info) -> float:
    """The DDS sample's source (write) timestamp from rclpy's message info, wall s."""
    return info["source_timestamp"] * 1e-9
