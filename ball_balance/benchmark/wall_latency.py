"""Camera-to-command latency on the wall clock, from the DDS samples' own write times.

A frame's stamp is its capture time on the graph's clock: simulated time in the simulated
graph, where the controller's and the monitor's "now" follow /clock in 10 ms steps (so a
difference of stamps reads about 0 or even negative), the wall clock with a real camera.
What a user waits for is wall-clock time, so this measures it there:

  capture (wall)  the frame's stamp mapped to the wall clock through the /clock samples:
                  each says "simulated time t was reached at wall time w" (w: the DDS
                  source timestamp, written by the simulation loop that also captures the
                  frames), and the offset w - t is interpolated at the stamp; without /clock
                  samples the stamps already are wall-clock times
  command (wall)  the DDS source timestamp of the first command written after the frame's
                  /ball_state was written (the command that acts on it)

latency = command - capture, per /ball_state followed by a command. The same pairing as
benchmarks/latency_budget_bench.py's "capture -> command written" (which takes the capture
time from the simulation's latency trace instead of the /clock map).
Plain Python, no ROS: the monitor (ball_balance/benchmark/live.py) and the benchmark feed it.
"""
from __future__ import annotations

import bisect

import numpy as np


class CameraToCommand:
    def __init__(self) -> None:
        self._clock_sim_s: list[float] = []     # /clock: simulated time ...
        self._clock_offset_s: list[float] = []  # ... and (wall written - simulated), s
        self._states: list[tuple[float, float]] = []   # (frame stamp s, /ball_state written wall s)
        self._commands_wall_s: list[float] = []        # command written, wall s

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

    def add_command(self, written_wall_s: float) -> None:
        self._commands_wall_s.append(written_wall_s)

    def capture_wall_s(self, stamp_s: float) -> float:
        """A stamp on the wall clock: through the /clock samples when there are any, else as is."""
        if not self._clock_sim_s:
            return stamp_s
        return stamp_s + float(np.interp(stamp_s, self._clock_sim_s, self._clock_offset_s))

    def latencies_s(self) -> np.ndarray:
        """Capture -> first command written after the frame's /ball_state, s, per state."""
        commands = sorted(self._commands_wall_s)
        # no extrapolation past the last /clock sample read: slower than real time, the offset
        # grows by (1 - real-time factor) per simulated second, and a monitor that read its
        # states ahead of its clock put seconds of that into the latency
        last_clock_s = self._clock_sim_s[-1] if self._clock_sim_s else float("inf")
        out = []
        for stamp_s, state_written_s in self._states:
            if stamp_s > last_clock_s:
                continue
            i = bisect.bisect_right(commands, state_written_s)
            if i < len(commands):
                out.append(commands[i] - self.capture_wall_s(stamp_s))
        return np.array(out, dtype=float)


def source_wall_s(info) -> float:
    """The DDS sample's source (write) timestamp from rclpy's message info, wall s."""
    return info["source_timestamp"] * 1e-9
