"""onnx_policy_controller/OnnxPolicyController: a learned policy (ONNX, onnxruntime) as a controller.

The model file says what it needs (policy_model.py in this folder): observation names with
their normalisation, action names, scale and limits, the rate it was trained at. This
controller knows nothing of the robot or task; it wires those names to interfaces:

Observation: every element of the model's observation is named `<source>` or
`<source>[k]` (k = that many inferences ago, kept by the controller). A source is a claimed
state interface (`state_interfaces`, e.g. `joint1/position`), a named input received on
`~/inputs` (std_msgs/Float64MultiArray, values in `inputs` order, or `set_inputs()` from
Python), or `command.<i>`, the i-th command this controller wrote; `observation_sources`
renames (`model_name=source`). A name that resolves to nothing refuses the model at
configure, as does any mismatch of its metadata with the parameters (one line each).

Action: one command interface per action (`command_interfaces`, the model's order). The
command is action * scale, added to `base_inputs` (one source per action) for a model whose
action kind is `residual_*`; blended in from the command held at activation over `blend_s`;
rate limited (`max_rate` per second); clamped to the model's [low, high] and, for joints of
the robot description, to their limits (manager/joint_limits.JointLimiter).

Timing: the controller runs every cycle of its update rate; an inference is due every
1/rate_hz of the model, on that grid (at an update rate that is not a whole multiple, at the
first cycle at or after its time: up to one cycle late, the model's rate on average). With
`async_inference` (default) it runs in a worker thread
(manager/async_handler.AsyncHandler): update() hands over a copy of the observation and
never waits; the result is used from the first cycle after it is ready. An inference due
while the previous one still runs is missed: the last action is kept, and it is counted.

Safety: a non-finite observation (a NaN state, a non-finite input) or result never reaches
a command interface: the controller holds its last commands and counts it
(`refused_observations`); inputs older than `max_input_age_s` hold the same way
(`refused_stale_inputs`). Before the first action the commands hold what was there at
activation.

Reported: ~/statistics `<name>.inference_time/<field>` (us) and `<name>.data_age/<field>`
(s, age of the oldest input at each inference) in pal_statistics names; introspection
`missed_inferences`, `refused_observations`, `refused_stale_inputs`, `clamped_commands`,
`inference_time_us`; the counters also show in /diagnostics (WARN while they grow).
"""
from __future__ import annotations

import math
import re
import threading
import time as _time
from typing import List, Optional

import numpy as np

from ..controller_interface.base import ControllerInterface, InterfaceConfiguration, interface_configuration_type
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..manager.statistics import Stats
from ..parameters import Param
from .forward_command import ForwardCommandController
from .policy_model import PolicyModelError, PolicyRunner

_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")


def _names(values) -> List[str]:
    return [v for v in values if v]


class PolicyConfigError(ValueError):
    """The model does not fit the controller's parameters (one line)."""


class OnnxPolicyController(ControllerInterface):
    PARAMS = (
        Param("model_path", "", "ONNX policy model: a file path or package://<package>/<path in its share dir>",
              user_facing=True),
        Param("state_interfaces", [""], "state interfaces claimed (observation sources by their full name)",
              user_facing=True),
        Param("inputs", [""], "named inputs on ~/inputs (std_msgs/Float64MultiArray, this order)", user_facing=True),
        Param("observation_sources", [""], "renames, 'model_name=source' (default: a name is its own source)",
              user_facing=True),
        Param("command_interfaces", [""], "one command interface per action, in the model's action order",
              user_facing=True),
        Param("base_inputs", [""], "residual models: per action, the source its scaled action is added to",
              user_facing=True),
        Param("max_rate", 0.0, "largest change of a command per second (0: no limit)", "1/s", 0.0, 1e6,
              user_facing=True),
        Param("blend_s", 0.5, "after activation, blend from the held commands to the policy's over this long",
              "s", 0.0, 60.0, user_facing=True),
        Param("max_input_age_s", 0.0, "hold when an input is older than this (0: no check)", "s", 0.0, 60.0),
        Param("async_inference", True, "infer in a worker thread (the loop never waits for it)"),
        Param("inference_thread_priority", 45, "SCHED_FIFO priority of the inference worker (0: normal "
              "scheduling); below the loop's, so that, preempted, it does not hold Python's interpreter lock "
              "the loop waits for", "", 0, 99),
        Param("inference_on_loop_cpu", True, "the inference worker runs on the manager loop thread's CPU(s): "
              "below the loop's priority it then runs only while the loop sleeps and never takes the "
              "interpreter lock from a running cycle"),
    )

    # ---- configure: load the model and resolve every name -----------------------------------
    def on_configure(self, previous_state: State) -> CallbackReturn:
        try:
            self._configure()
        except PolicyConfigError as error:
            self.get_logger().error(f"{self.name}: {error}")
            return CallbackReturn.ERROR
        self.introspection.clear()
        for what in ("missed_inferences", "refused_observations", "refused_stale_inputs", "clamped_commands",
                     "inference_time_us", "inferences"):
            self.register_introspection(what, lambda w=what: float(getattr(self, w)))
        node = self.get_node()
        if node is not None and self._input_names and getattr(self, "_subscription", None) is None:
            from std_msgs.msg import Float64MultiArray
            self._subscription = node.create_subscription(Float64MultiArray, "~/inputs", self.on_inputs, 10)
        return CallbackReturn.SUCCESS

    def _configure(self) -> None:
        p = self.params
        if not p["model_path"]:
            raise PolicyConfigError("parameter 'model_path' is empty")
        try:
            self.runner = PolicyRunner.load(p["model_path"])
        except PolicyModelError as error:
            raise PolicyConfigError(str(error)) from None
        md = self.runner.metadata
        self._states = _names(p["state_interfaces"])
        self._input_names = _names(p["inputs"])
        self._commands = _names(p["command_interfaces"])
        where = f"policy model {self.runner.where}"
        if len(self._commands) != md.action.size:
            raise PolicyConfigError(f"{where}: {md.action.size} actions {md.action.names}, but "
                                    f"{len(self._commands)} command_interfaces")
        renames = {}
        for entry in _names(p["observation_sources"]):
            name, sep, source = entry.partition("=")
            if not sep or not name or not source:
                raise PolicyConfigError(f"observation_sources entry '{entry}' must be 'model_name=source'")
            renames[name.strip()] = source.strip()
        # every source gets a column in a history table; (column, k) per observation element
        self._sources: List[str] = []
        columns = {}
        depth = 1
        index = []
        for element in md.observation.names:
            match = _INDEXED.match(element)
            name, k = (match.group(1), int(match.group(2))) if match else (element, 0)
            source = renames.get(name, name)
            if source not in columns:
                self._check_source(source, element, where)
                columns[source] = len(self._sources)
                self._sources.append(source)
            index.append((columns[source], k))
            depth = max(depth, k + 1)
        self._residual = md.action.kind.startswith("residual")
        bases = _names(p["base_inputs"])
        if self._residual and len(bases) != md.action.size:
            raise PolicyConfigError(f"{where}: action kind '{md.action.kind}' needs base_inputs, one per action "
                                    f"({md.action.size}), got {len(bases)}")
        if not self._residual and bases:
            raise PolicyConfigError(f"{where}: action kind '{md.action.kind}' takes no base_inputs")
        for b in bases:
            self._check_source(b, "base_inputs", where)
        self._bases = bases
        self._history = np.zeros((depth, len(self._sources)))
        self._frame = np.zeros(len(self._sources))
        self._rows = np.array([k for _, k in index], dtype=int)
        self._cols = np.array([c for c, _ in index], dtype=int)
        self._obs = np.zeros(md.observation.size)
        self._limiter = self._joint_limiter()
        self._input_lock = threading.Lock()
        self._inputs = np.full(len(self._input_names), np.nan)
        self._input_time = -math.inf
        self.inference_stats, self.age_stats = Stats(), Stats()
        self.statistics = [("inference_time", self.inference_stats), ("data_age", self.age_stats)]
        self.missed_inferences = self.refused_observations = self.refused_stale_inputs = 0
        self.clamped_commands = self.inferences = 0
        self.inference_time_us = float("nan")

    def _check_source(self, source: str, element: str, where: str) -> None:
        if source in self._states or source in self._input_names:
            return
        if source.startswith("command."):
            i = source[len("command."):]
            if i.isdigit() and int(i) < len(self._commands):
                return
        raise PolicyConfigError(f"{where}: observation '{element}' has no source '{source}' (not a claimed state "
                                f"interface {self._states}, an input {self._input_names} or command.<i>)")

    def _joint_limiter(self):
        """JointLimiter over the commanded joints' positions that the robot description limits."""
        getter = getattr(self, "get_robot_description", None)
        urdf = getter() if getter is not None else ""
        if not urdf:
            return None
        from ..manager.joint_limits import JointLimiter, limits_from_description
        limits = limits_from_description(urdf)
        joints = [c.rsplit("/", 1)[0] for c in self._commands if c.endswith("/position")]
        if not joints or len(joints) != len(self._commands) or not all(j in limits for j in joints):
            return None
        return JointLimiter(joints, limits, self.get_logger(), self.name)

    def command_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, list(self._commands))

    def state_interface_configuration(self) -> InterfaceConfiguration:
        return InterfaceConfiguration(interface_configuration_type.INDIVIDUAL, list(self._states))

    # ---- inputs (executor thread) ---------------------------------------------------------
    def on_inputs(self, msg) -> None:
        self.set_inputs(msg.data)

    def set_inputs(self, values, now: Optional[float] = None) -> bool:
        """Store the named inputs (all of them, in `inputs` order); False (and counted) when the
        count is wrong. Non-finite values are stored: they hold the controller, counted there."""
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.shape[0] != len(self._input_names):
            self.get_logger().warning(f"{self.name}: ~/inputs needs {len(self._input_names)} values "
                                      f"{self._input_names}, got {values.shape[0]}")
            self.refused_observations += 1
            return False
        with self._input_lock:
            self._inputs[:] = values
            self._input_time = _time.monotonic() if now is None else now
        return True

    # ---- activation -------------------------------------------------------------------------
    def on_activate(self, previous_state: State) -> CallbackReturn:
        self._held = np.array([h.value for h in self.command_interfaces], dtype=float)
        if not np.all(np.isfinite(self._held)):   # no command yet: hold the measured position
            measured = {h.name: h.value for h in self.state_interfaces}
            self._held = np.array([measured.get(c, v) for c, v in zip(self._commands, self._held)], dtype=float)
        self._last = self._held.copy()
        # each source as (kind, handle or index), resolved once: update() touches no dict
        handles = {h.name: h for h in self.state_interfaces}
        self._readers = [self._reader(source, handles) for source in self._sources]
        self._base_readers = [self._reader(source, handles) for source in self._bases]
        self._action: Optional[np.ndarray] = None
        self._result: Optional[np.ndarray] = None
        self._result_seq = self._used_seq = 0
        self._history[:] = 0.0
        self._active_s = 0.0
        self._since_inference_s = math.inf
        self._pending = np.zeros(self.runner.metadata.observation.size)
        if self._limiter is not None:
            self._limiter.reset(list(self._last))
        if self.params["async_inference"]:
            from ..manager.async_handler import AsyncHandler
            self._worker = AsyncHandler(f"{self.name}.inference", self._infer_pending,
                                        thread_priority=self.params["inference_thread_priority"],
                                        on_trigger_cpus=self.params["inference_on_loop_cpu"])
        else:
            self._worker = None
        return CallbackReturn.SUCCESS

    def on_deactivate(self, previous_state: State) -> CallbackReturn:
        worker, self._worker = getattr(self, "_worker", None), None
        if worker is not None:
            worker.stop()
        return CallbackReturn.SUCCESS

    on_cleanup = ForwardCommandController.on_cleanup   # drops the ~/inputs subscription

    # ---- inference --------------------------------------------------------------------------
    def _infer_pending(self, time: float, period: float) -> return_type:
        """Worker thread (or inline): one inference on the observation handed over."""
        t0 = _time.perf_counter()
        action = self.runner.infer(self._pending)
        self.inference_time_us = (_time.perf_counter() - t0) * 1e6
        self.inference_stats.add(self.inference_time_us)
        self._result = action          # None: non-finite result
        self.inferences += 1
        self._result_seq += 1
        return return_type.OK

    def _reader(self, source: str, handles: dict):
        if source in handles:
            return ("state", handles[source])
        if source.startswith("command."):
            return ("command", int(source[len("command."):]))
        return ("input", self._input_names.index(source))

    def _read(self, reader, inputs: np.ndarray) -> float:
        kind, where = reader
        if kind == "state":
            return where.value
        return self._last[where] if kind == "command" else inputs[where]

    # ---- the loop ---------------------------------------------------------------------------
    def update(self, time: float, period: float) -> return_type:
        self._active_s += period
        self._since_inference_s += period
        with self._input_lock:
            inputs = self._inputs.copy()
            input_time = self._input_time
        # take a finished inference
        if self._result_seq != self._used_seq:
            self._used_seq = self._result_seq
            if self._result is None:
                self.refused_observations += 1
            else:
                self._action = self._result
        # an inference is due at the model's rate, on its grid: in a loop whose rate is not a
        # whole multiple (a 60 Hz model at 500 Hz: every 8 or 9 cycles) the remainder carries
        # over, so the average is the model's rate; after a gap (the first cycle) from now
        model_period_s = 1.0 / self.runner.metadata.rate_hz
        due = self._since_inference_s + 1e-9 >= model_period_s
        if due:
            self._since_inference_s -= model_period_s
            if not self._since_inference_s < model_period_s:
                self._since_inference_s = 0.0
            for j, reader in enumerate(self._readers):
                self._frame[j] = self._read(reader, inputs)
            age = _time.monotonic() - input_time if self._input_names else 0.0
            max_age = self.params["max_input_age_s"]
            if not np.all(np.isfinite(self._frame)):
                self.refused_observations += 1
            elif max_age > 0.0 and age > max_age:
                self.refused_stale_inputs += 1
            else:
                self._history[1:] = self._history[:-1]
                self._history[0] = self._frame
                self._obs[:] = self._history[self._rows, self._cols]
                self.age_stats.add(age)
                if self._worker is None:
                    self._pending[:] = self._obs
                    self._infer_pending(time, period)
                    self._used_seq = self._result_seq
                    if self._result is None:
                        self.refused_observations += 1
                    else:
                        self._action = self._result
                elif self._worker.busy:
                    self.missed_inferences += 1      # the last action is kept
                else:
                    self._pending[:] = self._obs
                    self._worker.trigger(time, period)
        if self._action is None:
            target = self._last
        else:
            target = self._command(self._action, inputs)
        self._write(target, period)
        return return_type.OK

    def _command(self, action: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        blend = 1.0 if self.params["blend_s"] <= 0 else min(1.0, self._active_s / self.params["blend_s"])
        scaled = action * self.runner.scale
        if self._residual:
            base = np.array([self._read(reader, inputs) for reader in self._base_readers])
            value = base + blend * scaled
        else:
            value = self._held + blend * (scaled - self._held)
        return np.clip(value, self.runner.low, self.runner.high)

    def _write(self, target: np.ndarray, period: float) -> None:
        if not np.all(np.isfinite(target)):
            self.refused_observations += 1
            target = self._last
        max_rate = self.params["max_rate"]
        if max_rate > 0.0 and period > 0.0:
            step = max_rate * period
            target = np.clip(target, self._last - step, self._last + step)
        if self._limiter is not None:
            limited = np.array(self._limiter.limit_positions(list(target), period))
            if np.any(limited != target):
                self.clamped_commands += 1
            target = limited
        self._last = np.asarray(target, dtype=float).copy()
        for handle, value in zip(self.command_interfaces, self._last):
            handle.value = float(value)
