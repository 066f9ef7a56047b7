"""Running statistics (ros2_control's MovingAverageStatistics) without per-sample allocation.

`Stats.add(x)` updates max, min, average, standard deviation (Welford), sample_count and
current_value in O(1). `STAT_FIELDS` are ros2_control's entry names, in its order.
"""
from __future__ import annotations

import math

STAT_FIELDS = ("max", "min", "average", "standard_deviation", "sample_count", "current_value")


class Stats:
    __slots__ = ("max", "min", "average", "_m2", "sample_count", "current_value")

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.max = float("nan")
        self.min = float("nan")
        self.average = float("nan")
        self._m2 = 0.0
        self.sample_count = 0
        self.current_value = float("nan")

    def add(self, x: float) -> None:
        n = self.sample_count + 1
        self.sample_count = n
        self.current_value = x
        if n == 1:
            self.max = self.min = self.average = x
            self._m2 = 0.0
            return
        if x > self.max:
            self.max = x
        if x < self.min:
            self.min = x
        delta = x - self.average
        self.average += delta / n
        self._m2 += delta * (x - self.average)

    @property
    def standard_deviation(self) -> float:
        n = self.sample_count
        return math.sqrt(self._m2 / n) if n > 1 else (0.0 if n == 1 else float("nan"))

    def get(self, name: str) -> float:
        return float(getattr(self, name))


class PeriodicityStats:
    """Execution time (us) and periodicity (Hz) of something run repeatedly.

    The first call only records the start time: there is no previous run, so no bogus
    periodicity sample (ros2_control reports one).
    """

    __slots__ = ("execution_time", "periodicity", "_last_start")

    def __init__(self):
        self.execution_time = Stats()  # microseconds
        self.periodicity = Stats()  # Hz
        self._last_start = None

    def add(self, start: float, end: float) -> None:
        """Record one run from `start` to `end` (seconds, monotonic)."""
        last = self._last_start
        if last is not None and start > last:
            self.periodicity.add(1.0 / (start - last))
        self._last_start = start
        self.execution_time.add((end - start) * 1e6)

    def reset(self) -> None:
        self.execution_time.reset()
        self.periodicity.reset()
        self._last_start = None


class ExecutionTime:
    """The manager's per-cycle times in us, ros2_control's `ControllerManagerExecutionTime`:
    read, update, write and total (read + update + write, switch included) of the last cycle;
    the switch phases of the last cycle that applied a switch and 0 in the others.
    Chained-mode changes happen inside activation and deactivation here: that time is 0."""

    FIELDS = ("update_time", "read_time", "write_time", "total_time", "switch_time", "switch_chained_mode_time",
              "switch_perform_mode_time", "deactivation_time", "activation_time")
    __slots__ = FIELDS

    def __init__(self):
        for name in self.FIELDS:
            setattr(self, name, 0.0)

    def new_cycle(self) -> None:
        """Called when a cycle starts: the switch phases are 0 unless this cycle switches."""
        self.switch_time = self.switch_chained_mode_time = self.switch_perform_mode_time = 0.0
        self.deactivation_time = self.activation_time = 0.0
