"""Watch (and record) a running balance graph: progress lines, then metrics, a PNG plot and
a short camera video with an overlay. Used by scripts/sim_*.sh (progress) and
scripts/run_demo.sh (the artifacts), and for the live-graph benchmark cells.

    python -m ball_balance.benchmark.live --duration 30 --out artifacts/demo --video-s 8

Subscribes /sim/ball_truth (true ball, plate frame), /ball_state (tracker), /ball_reference,
/plate_cmd, /sim/ball_dropped, /sim/ball_pushed (each push: the recovery from it is timed as
the benchmark does), /sim/ball_force (each change of the force on the ball: a step, timed
likewise), /clock (only for the wall-clock figures) and, for the video,
/camera/image_raw or the tracker's overlay (/ball_tracker/debug_image). For the progress
line only, the robot manager's /robot_manager/events and /robot_manager/transition_event (is
the command applied?).

The progress line shows the state at its stamp: DROPPED while the truth there shows the ball off
the plate (not after /sim/reset_ball or /sim/reset_world put it back; the metrics still end at the
first drop and count it); `tilt` is the commanded tilt (/plate_cmd) while the robot manager is
active (or absent: no event from it), the arm executing it; otherwise the column reads `cmd` and
the line ends "not applied (robot manager STATE)" or "not applied (emergency stop)": the arm
does not follow /plate_cmd then (after an emergency stop it holds its last position). A robot
manager's state change carries no stamp: it counts from the newest stamp read when it arrived.

One time base, the header stamps (simulated time in the simulated graph, which in lock-step
runs as slowly as the machine makes the control chain): never the time a message was read,
nor this node's clock. A slow machine, or a monitor that falls behind its topics, changes
when the samples are read, not what the figures say:

- every topic is read whole: reliable where its publisher is (/ball_reference, /plate_cmd,
  /sim/ball_pushed, /sim/ball_force), best effort where it is not (/sim/ball_truth and
  /ball_state are sensor data), RECORD_DEPTH deep, the callbacks append only;
- the recording counts up to the stamp every topic has been read to (`covered_until_s`), so
  a topic still queued is waited for, not held over;
- the error is the true ball against the target at the truth's stamp (between the two
  targets around it, as the benchmark takes it) and the tilt is the command in force then;
  metrics count from the controller's engagement (its first /ball_reference);
- the run ends when every topic has been read to --duration of stamped time after the first
  truth (or to the truth showing the ball off the plate); a topic that stops short of it is
  waited for DRAIN_WALL_S, then the figures cover what every topic covers, and say so;
- camera-to-command: header stamps, a frame's capture -> the /plate_cmd answering its
  /ball_state (wall_latency.py); the wall-clock figure is reported beside it, labelled;
- each video frame's overlay is the data at the frame's own stamp, and frames are encoded
  as the run goes, so the files are written within seconds of the end.

The metrics are plain Python (`live_metrics(Recording)`, no ROS), tested on a lock-stepped
benchmark episode. Exit code 0 when the ball stayed on the plate, 1 when it dropped, 2 when
nothing arrived.
"""
from __future__ import annotations

import argparse
import bisect
import math
import sys
import time
from collections import deque
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ball_balance.benchmark.metrics import RECOVER_HOLD_S, episode_metrics
from ball_balance.benchmark.wall_latency import CameraToCommand, source_wall_s

REFERENCE_FRESH_S = 0.1   # /ball_reference older than this: the controller is not engaged
PUSH_TIMED_S = 1.0 + RECOVER_HOLD_S   # a push is timed when the recording goes on this long after it
# samples a subscription keeps unread: Fast DDS keeps at most 5000 (its readers' max_samples,
# which a deeper keep-last queue does not raise: it then refuses the newer samples instead);
# 50 s of /sim/ball_truth at 100 Hz, 83 s of the 60 Hz topics
RECORD_DEPTH = 5000
DRAIN_WALL_S = 10.0       # at the end, stop waiting for the other topics after this long without progress
STAMP_MATCH_S = 1e-6      # header stamps are whole nanoseconds: one frame's stamp survives as one
PLOT_POINTS = 20000       # the plot draws at most this many samples per line
ROBOT_MANAGER = "/robot_manager"   # its state tells whether the arm executes /plate_cmd


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


# ---- sampling stamped series at other stamps (plain numpy) -----------------------------------
def held_before(stamps: np.ndarray, values: np.ndarray, t: np.ndarray):
    """Zero-order hold: at each t, the values of the newest row stamped strictly before t (a
    command stamped t has not acted at t yet); zeros and False where there is none."""
    i = np.searchsorted(stamps, t, side="left") - 1
    ok = i >= 0
    out = np.zeros((len(t), values.shape[1]))
    out[ok] = values[i[ok]]
    return out, ok


def reference_at(stamps: np.ndarray, points: np.ndarray, t: np.ndarray):
    """The target at each t and whether the controller was engaged then: engaged while a
    target at most REFERENCE_FRESH_S old exists (the controllers publish one every engaged
    tick); between two targets of one engaged stretch, the target at t itself (held, a target
    moving on a circle would lead or trail the ball by up to a control period of its motion);
    after a stretch, the last target stays the reference; nan before the first target."""
    last = np.searchsorted(stamps, t, side="right") - 1      # the newest target at each t
    before = np.maximum(last, 0)
    published = last >= 0
    if not len(stamps):
        return np.full((len(t), 2), np.nan), published
    ref = np.where(published[:, None], points[before], np.nan)
    engaged = published & (t - stamps[before] <= REFERENCE_FRESH_S)
    after = np.minimum(last + 1, len(stamps) - 1)
    span = stamps[after] - stamps[before]
    between = published & (after > last) & (span <= REFERENCE_FRESH_S)
    w = np.where(between, (t - stamps[before]) / np.where(between, span, 1.0), 0.0)[:, None]
    return np.where(between[:, None], (1.0 - w) * points[before] + w * points[after], ref), engaged


class Stamped:
    """One topic's samples as read: rows (header stamp s, values...); adding one is O(1)."""

    __slots__ = ("rows", "first_s", "last_s", "width")

    def __init__(self, width: int) -> None:
        self.rows: list = []
        self.first_s, self.last_s, self.width = math.inf, -math.inf, width

    def add(self, row: tuple) -> None:
        self.rows.append(row)
        self.first_s, self.last_s = min(self.first_s, row[0]), max(self.last_s, row[0])

    def __len__(self) -> int:
        return len(self.rows)

    def array(self) -> np.ndarray:
        """All rows, in stamp order."""
        a = np.array(self.rows, dtype=float).reshape(-1, self.width)
        return a[np.argsort(a[:, 0], kind="stable")]

    def near(self, t_s: float, k: int = 3) -> np.ndarray:
        """The rows around stamp t_s (k each side), in stamp order: enough for the lookups
        above, which only look at the neighbours of t (rows arrive in stamp order)."""
        i = bisect.bisect_right(self.rows, t_s, key=lambda row: row[0])
        a = np.array(self.rows[max(0, i - k):i + k], dtype=float).reshape(-1, self.width)
        return a[np.argsort(a[:, 0], kind="stable")]


class Recording:
    """What the monitor read, stamped. Plain Python: the callbacks take anything with the
    messages' fields (tests feed it directly; LiveRecorder subscribes them)."""

    def __init__(self) -> None:
        self.truth = Stamped(4)        # stamp, x, y, on the plate (1/0)
        self.states = Stamped(5)       # stamp, x, y, tracking_valid, markers_found
        self.references = Stamped(3)   # stamp, x, y
        self.commands = Stamped(3)     # stamp, u_x, u_y
        self.pushes: list = []         # stamps of the pushes applied
        self.force_changes: list = []  # stamps of the changes of the constant force on the ball
        self.latency = CameraToCommand()
        self.dropped = False           # /sim/ball_dropped said so
        self.drop_s: Optional[float] = None   # first truth stamp with the ball off the plate
        # the robot manager's state changes (newest stamp read on arrival, lifecycle state label
        # or "emergency stop"), in arrival order
        self.manager: list = []
        self.clip: Optional[VideoClip] = None

    # --- callbacks: O(1) ------------------------------------------------------------------
    def on_truth(self, msg) -> None:
        t = stamp_s(msg)
        self.truth.add((t, msg.x, msg.y, float(bool(msg.ball_found))))
        if not msg.ball_found and (self.drop_s is None or t < self.drop_s):
            self.drop_s = t

    def on_state(self, msg, written_wall_s: float = math.nan) -> None:
        t = stamp_s(msg)
        self.states.add((t, msg.x, msg.y, float(bool(msg.tracking_valid)), float(msg.markers_found)))
        self.latency.add_state(t, written_wall_s)

    def on_reference(self, msg) -> None:
        self.references.add((stamp_s(msg), msg.point.x, msg.point.y))

    def on_command(self, msg, written_wall_s: float = math.nan) -> None:
        t = stamp_s(msg)
        self.commands.add((t, msg.vector.x, msg.vector.y))
        self.latency.add_command(written_wall_s, t)

    def on_pushed(self, msg) -> None:
        self.pushes.append(stamp_s(msg))

    def on_force(self, msg) -> None:
        self.force_changes.append(stamp_s(msg))

    def on_clock(self, msg, written_wall_s: float) -> None:
        self.latency.add_clock(msg.clock.sec + msg.clock.nanosec * 1e-9, written_wall_s)

    def on_dropped(self, msg) -> None:
        self.dropped = self.dropped or bool(msg.data)

    def on_manager_event(self, msg) -> None:
        """/robot_manager/events (DiagnosticStatus): an emergency stop, or the lifecycle state
        after a transition, a failed one or a reset."""
        values = {kv.key: kv.value for kv in msg.values}
        state = "emergency stop" if values.get("event") == "emergency_stop" else values.get("lifecycle_state")
        if state:
            self._manager_state(state)

    def on_manager_transition(self, msg) -> None:
        """/robot_manager/transition_event: the state a transition goes to (deactivating at its
        start: the plate is being levelled, the command no longer applied)."""
        self._manager_state(msg.goal_state.label)

    def _manager_state(self, state: str) -> None:
        newest = max(self.truth.last_s, self.states.last_s, self.references.last_s, self.commands.last_s)
        self.manager.append((newest, state))

    def manager_at(self, t_s: float) -> Optional[str]:
        """The robot manager's state at stamp t_s; None before its first event (or without one)."""
        i = bisect.bisect_right(self.manager, t_s, key=lambda change: change[0])
        return self.manager[i - 1][1] if i else None

    # --- how far the recording goes -------------------------------------------------------
    @property
    def t0_s(self) -> float:
        """The first truth's stamp: the monitor's time 0."""
        return self.truth.first_s

    @property
    def engaged_s(self) -> float:
        """The controller's first target's stamp (inf before it)."""
        return self.references.first_s

    def covered_until_s(self) -> float:
        """The stamp up to which every topic the metrics use has been read (-inf before the
        first truth). /ball_reference comes only while the controller is engaged, with a
        /plate_cmd of the same stamp: read up to the commands' stamp less REFERENCE_FRESH_S
        when its targets stop (none is still queued then)."""
        ends = [self.truth.last_s]
        if len(self.commands):
            ends.append(self.commands.last_s)
            gap = self.commands.last_s - self.references.last_s
            ends.append(self.references.last_s if gap <= REFERENCE_FRESH_S
                        else self.commands.last_s - REFERENCE_FRESH_S)
        elif len(self.references):
            ends.append(self.references.last_s)
        return min(ends)

    def end_s(self, duration_s: float) -> float:
        """The stamp a run of duration_s (0: no end) ends at: duration_s after the first truth,
        or the first truth with the ball off the plate, whichever comes first."""
        if duration_s <= 0 or not len(self.truth):
            return math.inf
        return min(self.t0_s + duration_s, self.drop_s if self.drop_s is not None else math.inf)

    def at(self, t_s: float) -> dict:
        """The recording at one stamp: ball (truth, interpolated), on_plate (the newest truth at
        or before it), tracker (the /ball_state of exactly this stamp), target and tilt (as the
        metrics take them), manager (manager_at); None where unknown."""
        t = np.array([t_s])
        out = {"ball": None, "on_plate": None, "tracker": None, "target": None, "tilt": None,
               "manager": self.manager_at(t_s)}
        truth = self.truth.near(t_s)
        if len(truth) and truth[0, 0] <= t_s <= truth[-1, 0]:
            out["ball"] = (float(np.interp(t_s, truth[:, 0], truth[:, 1])),
                           float(np.interp(t_s, truth[:, 0], truth[:, 2])))
        upto = truth[truth[:, 0] <= t_s + STAMP_MATCH_S]
        if len(upto):
            out["on_plate"] = bool(upto[-1, 3])
        states = self.states.near(t_s)
        same = states[np.abs(states[:, 0] - t_s) <= STAMP_MATCH_S]
        if len(same):
            out["tracker"] = (float(same[0, 1]), float(same[0, 2]))
        refs = self.references.near(t_s)
        ref, engaged = reference_at(refs[:, 0], refs[:, 1:3], t)
        if engaged[0]:
            out["target"] = (float(ref[0, 0]), float(ref[0, 1]))
        commands = self.commands.near(t_s)
        tilt, ok = held_before(commands[:, 0], commands[:, 1:3], t)
        if ok[0]:
            out["tilt"] = (float(tilt[0, 0]), float(tilt[0, 1]))
        return out


# ---- metrics (plain Python) ----------------------------------------------------------------
def live_series(rec: Recording, end_s: float = math.inf) -> Optional[dict]:
    """Time series on the truth's stamps, from the controller's engagement to end_s (or as far
    as every topic was read, or the truth showing the ball off the plate): t (from the
    engagement), x, y (truth), rx, ry (target at t), ux, uy (tilt in force at t), mode
    (engaged), as the benchmark's episode records them; None before a truth and a target."""
    if len(rec.truth) < 2 or not len(rec.references):
        return None
    truth = rec.truth.array()
    truth = truth[truth[:, 0] <= min(end_s, rec.covered_until_s())]
    off = np.nonzero(truth[:, 3] == 0.0)[0]
    if len(off):
        truth = truth[:off[0] + 1]       # the episode ends with the step the ball left the plate on
    t = truth[:, 0]
    targets = rec.references.array()
    ref, engaged = reference_at(targets[:, 0], targets[:, 1:3], t)
    published = np.isfinite(ref[:, 0])
    if not np.any(published):
        return None
    # from the controller's engagement on (before that the tracker starts up; the ball rests)
    first = int(np.argmax(published))
    commands = rec.commands.array()
    cmd, _ = held_before(commands[:, 0], commands[:, 1:3], t)
    t = t[first:]
    return {"t": t - t[0], "x": truth[first:, 1], "y": truth[first:, 2], "rx": ref[first:, 0],
            "ry": ref[first:, 1], "ux": cmd[first:, 0], "uy": cmd[first:, 1], "age": np.full(len(t), np.nan),
            "mode": engaged[first:].astype(float), "t_engaged": np.array([t[0] - rec.t0_s]),
            "stamp_engaged": np.array([t[0]]), "on_plate": truth[first:, 3]}


def missing_samples(stamps: np.ndarray) -> int:
    """Samples missing from a series published at a fixed period (its median interval)."""
    dt = np.diff(stamps)
    if len(dt) < 2:
        return 0
    period = float(np.median(dt))
    return int(np.sum(np.maximum(np.round(dt / period) - 1.0, 0.0))) if period > 0 else 0


def live_metrics(rec: Recording, end_s: float = math.inf) -> Optional[dict]:
    """The benchmark's episode metrics (metrics.episode_metrics) of the recording up to end_s,
    plus camera-to-command on the stamps (latency_s, latency_p95_s) and on the wall clock
    (latency_wall_s, latency_wall_p95_s, real_time_factor), the tracker's valid fraction and
    the truth samples missing; None before a truth and a target."""
    s = live_series(rec, end_s)
    if s is None:
        return None
    engaged_at = float(s["stamp_engaged"][0])
    last_s = engaged_at + float(s["t"][-1])
    dropped = bool(s["on_plate"][-1] == 0.0) or (rec.dropped and math.isinf(end_s) and rec.drop_s is None)
    # a push too close to the end of the recording cannot be timed (the run stops while
    # the ball is still on its way back), nor one after it
    last_timed = last_s - PUSH_TIMED_S
    m = episode_metrics(s, dropped, float(s["t"][-1]),
                        push_times_s=[p - engaged_at for p in rec.pushes if engaged_at <= p <= last_timed],
                        step_times_s=[f - engaged_at for f in sorted(rec.force_changes) if engaged_at <= f < last_s])
    for key, latency in (("latency", rec.latency.stamp_latencies_s(engaged_at, last_s)),
                         ("latency_wall", rec.latency.latencies_s(engaged_at, last_s))):
        if latency.size:
            m[f"{key}_s"] = float(np.mean(latency))
            m[f"{key}_p95_s"] = float(np.percentile(latency, 95))
    m["real_time_factor"] = rec.latency.real_time_factor(engaged_at, last_s)
    if len(rec.states):
        states = rec.states.array()
        states = states[(states[:, 0] >= engaged_at) & (states[:, 0] <= last_s)]
        if len(states):
            m["tracking_valid_fraction"] = float(np.mean(states[:, 3]))
    truth = rec.truth.array()
    m["truth_samples_missing"] = float(missing_samples(truth[truth[:, 0] <= last_s, 0]))
    return m


def format_metrics(m) -> str:
    def ms(key):
        return 1e3 * m.get(key, math.nan)

    latency = "-"
    if math.isfinite(m.get("latency_p95_s", math.nan)):
        latency = f"mean {ms('latency_s'):.1f} ms, p95 {ms('latency_p95_s'):.1f} ms (stamps)"
    if math.isfinite(m.get("latency_wall_p95_s", math.nan)):
        latency += f"; wall clock p95 {ms('latency_wall_p95_s'):.0f} ms"
        if math.isfinite(m.get("real_time_factor", math.nan)):
            latency += f" at real-time factor {m['real_time_factor']:.2f}"
    return (f"drop {'YES' if m['drop'] else 'no'} | RMSE {1e3 * m['rmse_m']:.1f} mm | after 5 s "
            f"{1e3 * m['rmse_steady_m']:.1f} mm | settled to 5 mm at "
            f"{m['settle_s']:.1f} s | peak tilt {math.degrees(m['peak_tilt_rad']):.1f} deg | "
            f"tilt rate RMS {m['smoothness_rad_s']:.2f} rad/s | " +
            (f"push recovery mean {m['push_recover_s']:.2f} s, worst {m['push_recover_max_s']:.2f} s, "
             f"{m['pushes_late']:.0f} of {m['pushes']:.0f} over 1 s | " if m.get("pushes") else "") +
            (f"force steps: worst back within 5 mm after {m['step_recover_max_s']:.2f} s, "
             f"{1e3 * m['step_steady_m']:.1f} mm left, {m['steps_unrecovered']:.0f} of {m['steps']:.0f} "
             "not back | " if m.get("steps") else "") +
            f"camera-to-command {latency}")


def format_at(rec: Recording, t_s: float) -> str:
    """A progress line: the recording at stamp t_s."""
    now = rec.at(t_s)
    line = f"[monitor] t {t_s - rec.t0_s:6.1f} s"
    if now["ball"] is not None:
        x, y = now["ball"]
        line += f"  ball ({1e3 * x:+7.1f}, {1e3 * y:+7.1f}) mm"
    if now["target"] is not None:
        rx, ry = now["target"]
        line += f"  target ({1e3 * rx:+6.1f}, {1e3 * ry:+6.1f}) mm"
        if now["ball"] is not None:
            line += f"  error {1e3 * math.hypot(now['ball'][0] - rx, now['ball'][1] - ry):6.1f} mm"
    elif t_s < rec.engaged_s:
        line += "  (controller not engaged yet)"
    else:
        line += "  (controller not engaged)"
    not_applied = not_applied_because(now["manager"])
    if now["tilt"] is not None:   # the command: "cmd" (same width) when the arm does not execute it
        line += (f"  {'tilt' if not_applied is None else 'cmd '} "
                 f"({math.degrees(now['tilt'][0]):+5.2f}, {math.degrees(now['tilt'][1]):+5.2f}) deg")
    if now["on_plate"] is False:   # now: not since the first drop (the metrics keep that)
        line += "  DROPPED"
    if now["tilt"] is not None and not_applied is not None:
        line += f"  not applied ({not_applied})"
    return line


def not_applied_because(manager: Optional[str]) -> Optional[str]:
    """Why the arm does not execute /plate_cmd, from the robot manager's state (None: it does,
    the manager active or never heard from)."""
    if manager is None or manager == "active":
        return None
    return manager if manager == "emergency stop" else f"robot manager {manager}"


# ---- the video -------------------------------------------------------------------------------
class VideoClip:
    """MP4 of the camera frames stamped from the engagement on, in the window start_s ..
    start_s + length_s after the first truth, at most `fps` frames per second of stamped time,
    each with the recording at its own stamp written on it (ball, tracker, target, tilt).
    It plays in real time: output frame k shows the newest camera frame stamped at or before
    t_first + k / fps, so a 12 s window plays for 12 s however many frames the transport
    skipped. Frames are encoded as soon as every topic has been read past their stamp
    (`encode_ready`, from the monitor's loop, not its callbacks), so closing is immediate."""

    def __init__(self, path: Path, length_s: float, start_s: float = 0.0, fps: float = 15.0,
                 decode: Optional[Callable] = None) -> None:
        self.path, self.length_s, self.start_s, self.fps = Path(path), length_s, start_s, fps
        self.decode = decode or (lambda frame: frame)
        self.pending: deque = deque()    # (stamp s, frame) offered, not yet encoded
        self.frames = 0                  # camera frames in the clip
        self._last_offered_s = -math.inf
        self._writer = None
        self._size = None
        self._held = None                # the last frame added, written until the next one is due
        self._t_first = self._t_last = 0.0
        self._tick = 0

    def offer(self, stamp_s: float, frame, t0_s: float = -math.inf) -> None:
        """(callback) A camera frame: kept when it may belong in the clip; O(1)."""
        if stamp_s < self._last_offered_s + 1.0 / self.fps - STAMP_MATCH_S:
            return
        if math.isfinite(t0_s) and not self.start_s <= stamp_s - t0_s <= self.start_s + self.length_s:
            return
        self._last_offered_s = stamp_s
        self.pending.append((stamp_s, frame))

    def encode_ready(self, rec: Recording, most: int = 4, final: bool = False) -> None:
        """Encode up to `most` frames whose stamp every topic has been read past (all of them
        when final; frames past the recording are dropped then)."""
        covered = rec.covered_until_s()
        while self.pending and (final or most > 0) and self.pending[0][0] <= covered:
            stamp, frame = self.pending.popleft()
            t = stamp - rec.t0_s
            if stamp < rec.engaged_s or not self.start_s <= t <= self.start_s + self.length_s:
                continue
            image = self.decode(frame)
            if image is not None:
                self._add(t, image, overlay_lines(rec, stamp))
                most -= 1
        if final:
            self.pending.clear()

    def _add(self, t_s: float, image: np.ndarray, lines) -> None:
        import cv2

        if self._writer is None:
            h, w = image.shape[:2]
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w, h))
            self._size, self._t_first = (w, h), t_s
        if not self._writer.isOpened():
            return
        frame = np.array(image, dtype=np.uint8)   # writable, and off the message's buffer
        if frame.shape[1::-1] != self._size:
            frame = cv2.resize(frame, self._size)
        cv2.rectangle(frame, (0, 0), (self._size[0], 8 + 16 * len(lines)), (0, 0, 0), -1)
        for row, text in enumerate(lines):
            cv2.putText(frame, text, (6, 16 + 16 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1,
                        cv2.LINE_AA)
        if self._held is not None:     # the previous frame until this one is due
            while self._t_first + self._tick / self.fps < t_s - STAMP_MATCH_S:
                self._writer.write(self._held)
                self._tick += 1
        self._held, self._t_last = frame, t_s
        self.frames += 1

    def close(self) -> bool:
        """Write the last frame through its tick and finish the file; False without frames."""
        if self._writer is None:
            return False
        if self._held is not None and self._writer.isOpened():
            while self._tick <= round((self._t_last - self._t_first) * self.fps):
                self._writer.write(self._held)
                self._tick += 1
        self._writer.release()
        return self.frames > 0


def overlay_lines(rec: Recording, stamp: float) -> list:
    """The overlay of the frame stamped `stamp`: the recording at that same stamp."""
    def mm(point):
        return "-" if point is None else f"({1e3 * point[0]:+6.1f}, {1e3 * point[1]:+6.1f}) mm"

    now = rec.at(stamp)
    tilt = "-" if now["tilt"] is None else \
        f"({math.degrees(now['tilt'][0]):+5.2f}, {math.degrees(now['tilt'][1]):+5.2f}) deg"
    not_applied = not_applied_because(now["manager"])
    if now["tilt"] is not None and not_applied is not None:
        tilt = f"cmd {tilt} not applied ({not_applied})"
    return [f"t {stamp - rec.t0_s:6.2f} s  ball {mm(now['ball'])}  target {mm(now['target'])}",
            f"tracker {mm(now['tracker'])}  tilt {tilt}"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_run(s, path: Path, title: str) -> None:
    plt = _pyplot()
    step = max(1, -(-len(s["t"]) // PLOT_POINTS))   # a long run: every step-th sample
    s = {k: v[::step] if len(v) == len(s["t"]) else v for k, v in s.items()}
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    ax = axes[0]
    half = 0.457 / 2
    ax.plot([-half, half, half, -half, -half], [-half, -half, half, half, -half], "k-", lw=1)
    ax.plot(s["rx"], s["ry"], "g--", lw=1, label="reference")
    ax.plot(s["x"], s["y"], "C1-", lw=1, label="ball (truth)")
    ax.plot(s["x"][:1], s["y"][:1], "ko", label="release")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("ball path vs reference (plate frame)")
    ax.legend(fontsize=8)
    ax = axes[1]
    err = 1e3 * np.hypot(s["x"] - s["rx"], s["y"] - s["ry"])
    ax.plot(s["t"], err, "C0-", lw=1)
    ax.axhline(5.0, color="k", ls=":", lw=0.8)
    ax.axhline(10.0, color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|ball - reference| [mm]")
    ax.set_title("error over time")
    ax = axes[2]
    ax.plot(s["t"], np.degrees(s["ux"]), lw=1, label="u_x")
    ax.plot(s["t"], np.degrees(s["uy"]), lw=1, label="u_y")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("tilt command [deg]")
    ax.set_title("tilt commands")
    ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---- ROS -------------------------------------------------------------------------------------
class LiveRecorder(Recording):
    """The Recording, subscribed: every topic read whole (module docstring)."""

    def __init__(self, node, video_s: float = 0.0, video_start_s: float = 0.0, video_fps: float = 15.0,
                 video_topic: str = "/camera/image_raw", video_path: Optional[Path] = None):
        super().__init__()
        from ball_tracker_msgs.msg import BallState
        from diagnostic_msgs.msg import DiagnosticStatus
        from geometry_msgs.msg import PointStamped, Vector3Stamped
        from lifecycle_msgs.msg import TransitionEvent
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Bool

        self.node = node
        # best effort for the sensor-data publishers (a reliable reader would not match them);
        # reliable where the publisher is, so a sample the transport loses is sent again
        sensor = QoSProfile(depth=RECORD_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT)
        reliable = QoSProfile(depth=RECORD_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(BallState, "/sim/ball_truth", self.on_truth, sensor)
        node.create_subscription(BallState, "/ball_state",
                                 lambda msg, info: self.on_state(msg, source_wall_s(info)), sensor)
        node.create_subscription(PointStamped, "/ball_reference", self.on_reference, reliable)
        node.create_subscription(Vector3Stamped, "/plate_cmd",
                                 lambda msg, info: self.on_command(msg, source_wall_s(info)), reliable)
        node.create_subscription(Vector3Stamped, "/sim/ball_pushed", self.on_pushed, reliable)
        node.create_subscription(Clock, "/clock", lambda msg, info: self.on_clock(msg, source_wall_s(info)), sensor)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(Bool, "/sim/ball_dropped", self.on_dropped, latched)
        force_changes = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(Vector3Stamped, "/sim/ball_force", self.on_force, force_changes)
        # the robot manager (docs/robot_manager.md): its events are transient local (the last 20)
        events = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(DiagnosticStatus, f"{ROBOT_MANAGER}/events", self.on_manager_event, events)
        node.create_subscription(TransitionEvent, f"{ROBOT_MANAGER}/transition_event", self.on_manager_transition, 10)
        if video_s > 0 and video_path is not None:
            from sensor_msgs.msg import Image

            from ball_balance.ros.images import decode_image

            self.clip = VideoClip(video_path, video_s, video_start_s, video_fps,
                                  decode=lambda view: decode_image(view)[0])
            # serialized: the stamp is read without copying the pixels of frames left out
            node.create_subscription(Image, video_topic, self.on_image, qos_profile_sensor_data, raw=True)

    def on_image(self, serialized) -> None:
        from ball_balance.ros.images import image_from_cdr

        try:
            view = image_from_cdr(serialized)
        except ValueError:
            return
        self.clip.offer(stamp_s(view), view, self.t0_s)


def main(argv=None) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from controller_manager_py.ros.node_main import ignore_stop_signals

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=0.0,
                        help="stop after this much stamped (simulated) time; 0 = Ctrl-C")
    parser.add_argument("--out", default="", help="folder for plot.png, camera.mp4, metrics.txt")
    parser.add_argument("--title", default="ball_balance")
    parser.add_argument("--video-s", type=float, default=0.0, help="seconds of camera video to keep")
    parser.add_argument("--video-start-s", type=float, default=0.0, help="(frames start at engagement at the earliest)")
    parser.add_argument("--video-topic", default="/camera/image_raw",
                        help="image topic for the video, e.g. /ball_tracker/debug_image (the tracker's overlay)")
    parser.add_argument("--sim-time", action="store_true",
                        help="the graph runs on /clock (accepted for compatibility: all times are header stamps)")
    parser.add_argument("--progress-s", type=float, default=1.0, help="progress line period; 0 = quiet")
    args = parser.parse_args(argv)

    out = Path(args.out) if args.out else None
    rclpy.init()
    node = rclpy.create_node("ball_balance_monitor")
    rec = LiveRecorder(node, args.video_s, args.video_start_s, video_topic=args.video_topic,
                       video_path=out / "camera.mp4" if out is not None else None)
    if out is not None:
        _pyplot()   # imported now, while the graph starts, not at the end

    # one executor for the whole run: rclpy.spin_once(node) adds the node and removes it again
    # on every call, rebuilding the wait set per sample; at ~400 samples/s on a loaded machine
    # the monitor would fall seconds behind its topics
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    next_progress_s = None
    reached_s, reached_wall_s = -math.inf, time.monotonic()   # how far the topics were read, and when
    end_s = math.inf
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
            covered = rec.covered_until_s()
            if rec.clip is not None:
                rec.clip.encode_ready(rec)
            if args.progress_s > 0 and math.isfinite(covered):
                if next_progress_s is None:
                    next_progress_s = rec.t0_s
                if covered >= next_progress_s:
                    print(format_at(rec, next_progress_s), flush=True)
                    behind = math.ceil((covered - next_progress_s) / args.progress_s)   # lines to skip
                    next_progress_s += args.progress_s * max(1, behind)
            end_s = rec.end_s(args.duration)
            if covered >= end_s:
                break
            if covered > reached_s:
                reached_s, reached_wall_s = covered, time.monotonic()
            elif rec.truth.last_s >= end_s and time.monotonic() - reached_wall_s > DRAIN_WALL_S:
                break   # the truth reached the end, and another topic stopped short of it
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl-C / SIGTERM: still report what was recorded
    except Exception:
        # the signal shut the context down between rclpy.ok() and the wait, which then
        # raises "context is not valid": the same clean stop
        if rclpy.ok():
            raise
    ignore_stop_signals()  # a second Ctrl-C must not cut the report (and the files) short
    code = report(rec, end_s, args, out)
    try:
        node.destroy_node()
    except Exception:  # noqa: BLE001 - the context may already be shut down
        pass
    rclpy.try_shutdown()
    return code


def report(rec: Recording, end_s: float, args, out: Optional[Path]) -> int:
    """Print the metrics and write the files; the exit code."""
    covered = rec.covered_until_s()
    if math.isfinite(end_s) and covered < end_s:
        print(f"[monitor] the topics were read to t {covered - rec.t0_s:.1f} s only (of "
              f"{end_s - rec.t0_s:.1f} s): the metrics end there", file=sys.stderr)
    metrics = live_metrics(rec, end_s)
    if rec.clip is not None:
        rec.clip.encode_ready(rec, final=True)
    if metrics is None:
        print("[monitor] no /sim/ball_truth received, or the controller never engaged", file=sys.stderr)
        return 2
    print("[monitor] " + format_metrics(metrics), flush=True)
    if metrics["truth_samples_missing"]:
        print(f"[monitor] {metrics['truth_samples_missing']:.0f} /sim/ball_truth samples were lost in "
              "transport (gaps in the series)", file=sys.stderr)
    if out is not None:
        started = time.monotonic()
        out.mkdir(parents=True, exist_ok=True)
        s = live_series(rec, end_s)
        (out / "metrics.txt").write_text("".join(f"{k}: {v:.6g}\n" for k, v in metrics.items()))
        np.savez_compressed(out / "series.npz", **s)
        plot_run(s, out / "plot.png", args.title)
        print(f"[monitor] wrote {out / 'plot.png'}, {out / 'metrics.txt'} "
              f"({time.monotonic() - started:.1f} s)", flush=True)
        if rec.clip is not None:
            if rec.clip.close():
                print(f"[monitor] wrote {out / 'camera.mp4'} ({rec.clip.frames} camera frames)", flush=True)
            else:
                print("[monitor] no camera video (no frames received)", flush=True)
    return 1 if metrics["drop"] else 0


if __name__ == "__main__":
    sys.exit(main())
