"""The plate's way back to level when the robot manager deactivates: a smooth joint path.

q(t) = q0 + (q1 - q0) s(t / T), s(u) = 10u^3 - 15u^4 + 6u^5 (quintic smoothstep): starts and
ends at rest with zero acceleration, peak speed 1.875 |q1 - q0| / T. The duration T is the
longer of `min_duration_s` and what keeps every joint under `max_speed_rad_s`.
"""
from __future__ import annotations

from typing import List, Sequence

SMOOTHSTEP_PEAK = 1.875


def smoothstep(u: float) -> float:
    u = min(1.0, max(0.0, u))
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


def levelling_duration(q0: Sequence[float], q1: Sequence[float], max_speed_rad_s: float,
                       min_duration_s: float) -> float:
    """T (s): at least min_duration_s, long enough that no joint exceeds max_speed_rad_s."""
    largest = max((abs(b - a) for a, b in zip(q0, q1, strict=True)), default=0.0)
    return max(min_duration_s, SMOOTHSTEP_PEAK * largest / max_speed_rad_s)


def levelling_path(q0: Sequence[float], q1: Sequence[float], duration_s: float,
                   points: int) -> List[tuple]:
    """`points` samples (time_from_start s, positions) of the path, the last at duration_s."""
    out = []
    for k in range(1, points + 1):
        t = duration_s * k / points
        s = smoothstep(k / points)
        out.append((t, [a + (b - a) * s for a, b in zip(q0, q1, strict=True)]))
    return out
