"""The entries of ~/statistics and ~/introspection_data: (name, getter) pairs, ros2_control's names.

statistics (`<cm>` is the manager node's name, `controller_manager` by default):
  `<controller>.stats/execution_time/<field>` (us), `<controller>.stats/periodicity/<field>` (Hz)
  `<hw>.stats/read_cycle/{execution_time,periodicity}/<field>`, same for `write_cycle`
  `<cm>.{update,read,write,total,switch,switch_chained_mode,switch_perform_mode,deactivation,
  activation}_time` (us, the last cycle's; ros2_control Jazzy's names)
  with <field> in max, min, average, standard_deviation, sample_count, current_value.
  Our additions: `<cm>.stats/periodicity/<field>` (Hz) and `<cm>.stats/execution_time/<field>`
  (us, total time) over the diagnostics window, `<cm>.overruns` and `<cm>.skipped_periods`
  (counts since start); a controller's own `statistics` list of (name, Stats) as
  `<controller>.<name>/<field>`.
introspection_data:
  `state_interface.<name>`, `command_interface.<name>`, `command_interface.<name>.is_limited`
  (for joints with limits), `<component>.<variable>` and `<controller>.<variable>` registered
  in on_configure, `<component>.limited_commands` (commands changed by the joint limits
  stage since start), `<component>.data_age` (s, async hardware) and
  `<controller>.skipped_async_triggers` (async controllers).
The getters read live values; they are called from the publishing timer, not the loop.
"""
from __future__ import annotations

from typing import Callable, List, Tuple

from .statistics import STAT_FIELDS, PeriodicityStats, Stats

Entry = Tuple[str, Callable[[], float]]


def _stats(prefix: str, stats: Stats) -> List[Entry]:
    return [(f"{prefix}/{f}", (lambda s=stats, f=f: getattr(s, f))) for f in STAT_FIELDS]


def _periodic(prefix: str, stats: PeriodicityStats) -> List[Entry]:
    return [*_stats(f"{prefix}/execution_time", stats.execution_time),
            *_stats(f"{prefix}/periodicity", stats.periodicity)]


def statistics_entries(cm, cm_name: str = "controller_manager") -> List[Entry]:
    times = cm.execution_time
    entries: List[Entry] = [(f"{cm_name}.{f}", (lambda f=f: getattr(times, f))) for f in times.FIELDS]
    entries += [*_periodic(f"{cm_name}.stats", cm.loop_stats),
                (f"{cm_name}.overruns", lambda: cm.overruns),
                (f"{cm_name}.skipped_periods", lambda: cm.skipped_updates)]
    for comp in list(cm.rm.components.values()):
        entries += _periodic(f"{comp.name}.stats/read_cycle", comp.read_stats)
        entries += _periodic(f"{comp.name}.stats/write_cycle", comp.write_stats)
    for spec in list(cm.controllers.values()):
        entries += _periodic(f"{spec.name}.stats", spec.stats)
        # a controller's own running statistics (e.g. onnx_policy's inference_time, data_age)
        for what, stats in list(getattr(spec.c, "statistics", ())):
            entries += _stats(f"{spec.name}.{what}", stats)
    return entries


def introspection_entries(cm) -> List[Entry]:
    rm = cm.rm
    entries: List[Entry] = [(f"state_interface.{n}", (lambda h=h: h.value))
                            for n, h in sorted(rm.state_interfaces.items())]
    limited = {name for c in rm.components.values() for name in c.limiter.limited_names()}
    for name, handle in sorted(rm.command_interfaces.items()):
        entries.append((f"command_interface.{name}", (lambda h=handle: h.value)))
        if name in limited:
            entries.append((f"command_interface.{name}.is_limited", (lambda h=handle: float(h.is_limited))))
    for comp in rm.components.values():
        entries += [(f"{comp.name}.{var}", getter) for var, getter in comp.plugin.introspection]
        if comp.limiter.limited_names():
            entries.append((f"{comp.name}.limited_commands", lambda c=comp: float(c.limiter.clamped)))
        if comp.info.is_async:
            entries.append((f"{comp.name}.data_age", lambda c=comp: c.data_age(cm.now())))
    for spec in list(cm.controllers.values()):
        entries += [(f"{spec.name}.{var}", getter) for var, getter in spec.c.introspection]
        if spec.async_handler is not None or spec.c.is_async:
            entries.append((f"{spec.name}.skipped_async_triggers",
                            lambda s=spec: s.async_handler.skipped if s.async_handler is not None else 0.0))
    return entries
