"""The entries of ~/statistics and ~/introspection_data: (name, getter) pairs, ros2_control's names.

statistics:
  `<controller>.stats/execution_time/<field>` (us), `<controller>.stats/periodicity/<field>` (Hz)
  `<hw>.stats/read_cycle/{execution_time,periodicity}/<field>`, same for `write_cycle`
  `controller_manager.stats/{read_time,update_time,write_time,total_time}/<field>` (us),
  `controller_manager.stats/periodicity/<field>` (Hz), `controller_manager.stats/skipped_periods`
  with <field> in max, min, average, standard_deviation, sample_count, current_value.
introspection_data:
  `state_interface.<name>`, `command_interface.<name>`, `command_interface.<name>.is_limited`
  (for joints with limits), `<component>.<variable>` and `<controller>.<variable>` registered
  in on_configure, `<component>.data_age` (s, async hardware) and
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


def statistics_entries(cm) -> List[Entry]:
    m = "controller_manager.stats"
    entries: List[Entry] = [*_stats(f"{m}/read_time", cm.read_time), *_stats(f"{m}/update_time", cm.update_time),
                            *_stats(f"{m}/write_time", cm.write_time),
                            *_stats(f"{m}/total_time", cm.loop_stats.execution_time),
                            *_stats(f"{m}/periodicity", cm.loop_stats.periodicity),
                            (f"{m}/skipped_periods", lambda: cm.skipped_updates)]
    for comp in list(cm.rm.components.values()):
        entries += _periodic(f"{comp.name}.stats/read_cycle", comp.read_stats)
        entries += _periodic(f"{comp.name}.stats/write_cycle", comp.write_stats)
    for spec in list(cm.controllers.values()):
        entries += _periodic(f"{spec.name}.stats", spec.stats)
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
        if comp.info.is_async:
            entries.append((f"{comp.name}.data_age", lambda c=comp: c.data_age(cm.now())))
    for spec in list(cm.controllers.values()):
        entries += [(f"{spec.name}.{var}", getter) for var, getter in spec.c.introspection]
        if spec.async_handler is not None or spec.c.is_async:
            entries.append((f"{spec.name}.skipped_async_triggers",
                            lambda s=spec: s.async_handler.skipped if s.async_handler is not None else 0.0))
    return entries
