"""Diagnostics roll-up like ros2_control's, as plain data (the node turns it into /diagnostics).

Three statuses: "Controllers Activity", "Hardware Components Activity", "Controller
Manager Activity". Each compares periodicity (mean error against the expected rate, and
standard deviation, in Hz) and execution time (mean and standard deviation, us) with the
`diagnostics.threshold.*` parameters (THRESHOLD_PARAMS, ros2_control's names and
defaults); the worst item sets the status level. Items with no samples yet are OK. The
statistics cover the time since the previous roll-up: the node asks the loop to reset them
after each one (`cm.request_stats_reset()`), so a slow start does not colour them forever.

Refused and limited commands: a controller's introspection entries named `refused_*`,
`clamped_*`, `limited_*` or `missed_*` (e.g. forward_command's `refused_commands`,
onnx_policy's `missed_inferences`) and each hardware component's joint-limits stage
(`limited_commands`) are listed with their counts; a count that grew since the previous
roll-up makes its status WARN, naming how many. Other introspection values a controller
registered `in_diagnostics` are listed as they are (key `<controller> <name>`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Tuple

from ..hardware_interface.types import State
from ..parameters import Param
from .statistics import PeriodicityStats

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
REFUSAL_PREFIXES = ("refused_", "clamped_", "limited_", "missed_")


def _thresholds(scope: str, what: str, metric: str, warn: float, error: float):
    base = f"diagnostics.threshold.{scope}.{what}.{metric}"
    unit = "Hz" if what == "periodicity" else "us"
    return (Param(f"{base}.warn", warn, f"{scope} {what} {metric} above this: WARN", unit=unit, min=0.0),
            Param(f"{base}.error", error, f"{scope} {what} {metric} above this: ERROR", unit=unit, min=0.0))


THRESHOLD_PARAMS = (
    *_thresholds("controller_manager", "periodicity", "mean_error", 5.0, 10.0),
    *_thresholds("controller_manager", "periodicity", "standard_deviation", 5.0, 10.0),
    *_thresholds("controllers", "periodicity", "mean_error", 5.0, 10.0),
    *_thresholds("controllers", "periodicity", "standard_deviation", 5.0, 10.0),
    *_thresholds("controllers", "execution_time", "mean_error", 1000.0, 2000.0),
    *_thresholds("controllers", "execution_time", "standard_deviation", 100.0, 200.0),
    *_thresholds("hardware_components", "periodicity", "mean_error", 5.0, 10.0),
    *_thresholds("hardware_components", "periodicity", "standard_deviation", 5.0, 10.0),
    *_thresholds("hardware_components", "execution_time", "mean_error", 1000.0, 2000.0),
    *_thresholds("hardware_components", "execution_time", "standard_deviation", 100.0, 200.0),
)


@dataclass
class Status:
    name: str
    level: int = OK
    message: str = "OK"
    values: List[Tuple[str, str]] = field(default_factory=list)
    problems: List[str] = field(default_factory=list)

    def grade(self, level: int, what: str) -> None:
        if level > OK:
            self.problems.append(what)
        self.level = max(self.level, level)

    def finish(self, ok_message: str) -> Status:
        self.message = ok_message if self.level == OK else "; ".join(self.problems)
        return self


def _level(value: float, thresholds: Mapping[str, float], key: str) -> int:
    if not math.isfinite(value):
        return OK
    if value > thresholds[f"{key}.error"]:
        return ERROR
    if value > thresholds[f"{key}.warn"]:
        return WARN
    return OK


def grade_stats(status: Status, who: str, stats: PeriodicityStats, expected_hz: float,
                thresholds: Mapping[str, float], scope: str, with_execution_time: bool = True) -> None:
    p, e = stats.periodicity, stats.execution_time
    mean_error = abs(p.average - expected_hz) if p.sample_count and expected_hz else float("nan")
    status.values += [(f"{who} periodicity average (Hz)", f"{p.average:.3f}"),
                      (f"{who} periodicity standard deviation (Hz)", f"{p.standard_deviation:.3f}"),
                      (f"{who} execution time average (us)", f"{e.average:.1f}"),
                      (f"{who} execution time standard deviation (us)", f"{e.standard_deviation:.1f}")]
    base = f"diagnostics.threshold.{scope}"
    for value, key, text in (
            (mean_error, f"{base}.periodicity.mean_error", "periodicity mean error"),
            (p.standard_deviation, f"{base}.periodicity.standard_deviation", "periodicity std dev")):
        level = _level(value, thresholds, key)
        status.grade(level, f"{who}: {text} {value:.2f} Hz")
    if with_execution_time:
        for value, key, text in (
                (e.average, f"{base}.execution_time.mean_error", "execution time mean"),
                (e.standard_deviation, f"{base}.execution_time.standard_deviation", "execution time std dev")):
            status.grade(_level(value, thresholds, key), f"{who}: {text} {value:.0f} us")


def grade_count(status: Status, who: str, what: str, value: float, counts: Dict[str, float]) -> None:
    """List a refusal counter; WARN when it grew since the previous roll-up (`counts` keeps it)."""
    key = f"{who}.{what}"
    previous = counts.get(key, 0.0)
    counts[key] = value
    status.values.append((f"{who} {what.replace('_', ' ')}", f"{value:.0f}"))
    if value > previous:
        status.grade(WARN, f"{who}: {value - previous:.0f} {what.replace('_', ' ')} since the last report "
                           f"({value:.0f} in all)")


def roll_up(cm, thresholds: Mapping[str, float], counts: Optional[Dict[str, float]] = None) -> List[Status]:
    """The three statuses for the manager `cm` (read from the executor thread). counts: the
    refusal counters of the previous roll-up, updated in place (None: every count is new)."""
    counts = {} if counts is None else counts
    controllers = Status("Controllers Activity")
    states: Dict[str, int] = {}
    for spec in list(cm.controllers.values()):
        states[spec.state.label] = states.get(spec.state.label, 0) + 1
        controllers.values.append((spec.name, spec.state.label))
        listed = getattr(spec.c, "diagnostic_values", ())
        for what, getter in list(spec.c.introspection):
            if what.startswith(REFUSAL_PREFIXES) or what in listed:
                try:
                    value = float(getter())
                except Exception:  # noqa: BLE001 - a counter that vanished with a reconfigure
                    continue
                if what.startswith(REFUSAL_PREFIXES):
                    grade_count(controllers, spec.name, what, value, counts)
                else:
                    controllers.values.append((f"{spec.name} {what}", f"{value:.4f}"))
        if spec.state == State.ACTIVE:
            grade_stats(controllers, spec.name, spec.stats, spec.effective_rate, thresholds, "controllers")
            if spec.async_handler is not None:
                controllers.values.append((f"{spec.name} skipped async triggers", str(spec.async_handler.skipped)))
    summary = ", ".join(f"{n} {label}" for label, n in sorted(states.items())) or "no controllers loaded"
    hardware = Status("Hardware Components Activity")
    for comp in list(cm.rm.components.values()):
        hardware.values.append((comp.name, comp.state.label))
        if comp.limiter.limited_names():
            grade_count(hardware, comp.name, "limited_commands", float(comp.limiter.clamped), counts)
        if comp.state == State.FINALIZED:
            hardware.grade(ERROR, f"{comp.name} is finalized")
        if comp.state in (State.ACTIVE, State.INACTIVE):
            grade_stats(hardware, f"{comp.name} read", comp.read_stats, comp.rw_rate, thresholds, "hardware_components")
            if comp.state == State.ACTIVE:
                grade_stats(hardware, f"{comp.name} write", comp.write_stats, comp.rw_rate, thresholds,
                            "hardware_components")
            age = comp.data_age(cm.now())
            if age == age:
                hardware.values.append((f"{comp.name} data age (s)", f"{age:.4f}"))
    manager = Status("Controller Manager Activity")
    grade_stats(manager, "update loop", cm.loop_stats, cm.update_rate, thresholds, "controller_manager",
                with_execution_time=False)
    slowest_hz = cm.loop_stats.periodicity.min  # the longest period since the previous report
    manager.values += [("update loop longest period (ms)",
                        f"{1e3 / slowest_hz:.3f}" if slowest_hz == slowest_hz and slowest_hz > 0 else "nan"),
                       ("overruns", str(cm.overruns)),
                       ("skipped periods (overruns)", str(cm.skipped_updates))]
    return [controllers.finish(summary), hardware.finish(f"{len(cm.rm.components)} component(s) OK"),
            manager.finish("update loop on time")]
