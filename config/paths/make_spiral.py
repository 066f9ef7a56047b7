#!/usr/bin/env python3
"""Writes spiral.csv beside this file: the benchmark's `spiral` reference (closed_loop_bench.py).

Two turns counter-clockwise in 16 s while the radius goes in from 0.10 m to 0.03 m and back
out, r(t) = 0.065 + 0.035 cos(2 pi t / 16), angle 2 pi t / 8, sampled every 0.2 s. The last
row is at 15.8 s: a looping CSV path returns to its first row one mean row spacing later, at
16 s, where the spiral starts again.
"""
import math
from pathlib import Path

PERIOD_S, TURNS, STEP_S = 16.0, 2, 0.2

rows = ["t_s,x_m,y_m",   # the header first: the loader takes a header on the first line only
        "# spiral in and out, r = 0.10 -> 0.03 -> 0.10 m, 2 turns in 16 s (written by make_spiral.py)"]
for k in range(int(round(PERIOD_S / STEP_S))):
    t = k * STEP_S
    r = 0.065 + 0.035 * math.cos(2 * math.pi * t / PERIOD_S)
    angle = 2 * math.pi * TURNS * t / PERIOD_S
    rows.append(f"{t:.1f},{r * math.cos(angle):.5f},{r * math.sin(angle):.5f}")
(Path(__file__).resolve().parent / "spiral.csv").write_text("\n".join(rows) + "\n")
