"""The controller manager core: controllers' lifecycle, switching, the read-update-write cycle.

No rclpy here. The ROS node (ros_interface.py) and the loop thread (loop.py) drive it;
tests drive it directly with synthetic time (`cycle(time, period)`).

Threads: load/configure/cleanup/unload and switch planning run in the caller's thread
(the executor); `cycle()` runs in the loop thread. A switch is handed to the loop as a
plan and applied at the start of the next cycle, so a cycle never sees a half-switched
state. Without a running loop (`loop_running` False) a switch is applied at once.
"""
from __future__ import annotations

import logging
import threading
import time as _time
from typing import Callable, Dict, List, Mapping, Optional

from ..controller_interface.base import ControllerInterface
from ..hardware_interface.types import CallbackReturn, State, return_type
from ..parameters import ParameterError
from ..plugins import CONTROLLER_GROUP, PluginError, load_class
from . import switching
from .controller_spec import ControllerSpec
from .resource_manager import ResourceManager
from .statistics import ExecutionTime, PeriodicityStats, Stats
from .throttle import Throttle


class ControllerError(RuntimeError):
    """A controller operation failed (the message names the controller and the reason)."""


class ControllerManager:
    def __init__(self, update_rate: int = 100, logger=None,
                 node_factory: Optional[Callable[[str], object]] = None,
                 controller_config: Optional[Mapping[str, Mapping]] = None):
        """update_rate: Hz; node_factory(name) -> an rclpy Node for a controller (None: no ROS);
        controller_config: {controller: {"type": ..., "fallback_controllers": [...]}}."""
        self.update_rate = int(update_rate)
        self.logger = logger or logging.getLogger("controller_manager")
        self.throttle = Throttle(self.logger)
        self.node_factory = node_factory
        self.release_node: Callable[[object], None] = lambda node: node.destroy_node()
        self.controller_config: Dict[str, Mapping] = dict(controller_config or {})
        self.rm = ResourceManager([], self.logger)
        self.robot_description = ""  # the URDF the hardware was loaded from
        self.controllers: Dict[str, ControllerSpec] = {}
        self.ordered: List[ControllerSpec] = []  # active, in chain order; replaced, never mutated
        self.lock = threading.RLock()  # serialises executor-side operations
        self.loop_running = False
        self._pending: Optional[switching.SwitchPlan] = None
        self._pending_activations: Optional[switching.SwitchPlan] = None
        self._switch_done = threading.Event()
        self._handoff = threading.Lock()  # pending plan: taken by the loop or withdrawn, never both
        self._cycle = 0
        self._failed: List[str] = []  # reused every cycle
        self._failed_controllers: List[ControllerSpec] = []
        self.version = 0  # bumped on every visible change (lists, activity, statistics names)
        # called after every such change, from whichever thread made it (the loop's included):
        # it must return at once, e.g. by waking the thread that publishes the change
        self.on_change: Callable[[], None] = lambda: None
        # the manager's own statistics: ros2_control's per-cycle times (us) and our windows
        self.execution_time = ExecutionTime()
        self.loop_stats = PeriodicityStats()
        self.read_time, self.update_time, self.write_time = Stats(), Stats(), Stats()
        self.skipped_updates = 0  # periods skipped by overruns (set by the loop)
        self.overruns = 0  # cycles that ended after the next deadline (set by the loop)
        # False once the process is stopping under the manager (the node: its ROS context was
        # shut down by Ctrl-C); a controller failing then is not a fault, and the loop ends
        self.alive: Callable[[], bool] = lambda: True
        self.stopping = False
        self._reset_stats = False

    # ---- time ---------------------------------------------------------------------------
    def now(self) -> float:
        """The time given to read/update/write: the hardware's simulated clock, else system time (s)."""
        clock = self.rm.clock_component
        return clock.plugin.now() if clock is not None else _time.time()

    # ---- hardware -----------------------------------------------------------------------
    def load_robot_description(self, urdf: str, node=None,
                               initial_states: Optional[Mapping[str, State]] = None,
                               enforce_command_limits: bool = True, require_limits: bool = True) -> None:
        """Load hardware from a URDF; components are activated unless `initial_states` says
        otherwise (ros2_control's hardware_components_initial_state). enforce_command_limits:
        ros2_control's switch for the joint limits stage; require_limits: refuse a
        revolute/prismatic joint without a URDF <limit>. Raises ResourceError."""
        with self.lock:
            if self.rm.components:
                raise ControllerError("a robot description is already loaded")
            rm = ResourceManager.from_description(urdf, self.update_rate, node, self.logger,
                                                  enforce_command_limits, require_limits)
            rm._clock = self.now
            self.rm = rm
            self.robot_description = urdf  # handed to controllers (get_robot_description())
            for name in rm.components:
                target = (initial_states or {}).get(name, State.ACTIVE)
                if target != State.UNCONFIGURED:
                    rm.set_component_state(name, target)
            self._changed()

    def set_hardware_component_state(self, name: str, target: State) -> State:
        """Drive a component through its lifecycle (executor thread). The loop skips the
        component from the next cycle until the hooks are done, so they never run
        concurrently with its read()/write(). Controllers using its interfaces are deactivated
        first (all of them for unconfigured/finalized, those commanding it for inactive); the
        log says which and how to come back. Raises ResourceError."""
        with self.lock:
            comp = self.rm.components.get(name)
            if comp is not None and comp.state == State.FINALIZED and target != State.FINALIZED:
                self.logger.error(f"hardware '{name}' is finalized and cannot become {target.label}: finalized "
                                  "is final in the hardware lifecycle; restart the controller manager to load "
                                  "it again")
                return comp.state
            stopped: List[str] = []
            if comp is not None and target in (State.INACTIVE, State.UNCONFIGURED, State.FINALIZED):
                # inactive hardware still reads: only the controllers commanding it must stop
                stopped = self._deactivate_users(name, commands_only=target == State.INACTIVE)
            if comp is not None:
                comp.transitioning = True
                self._wait_for_cycle()
            try:
                reached = self.rm.set_component_state(name, target)
            finally:
                if comp is not None:
                    comp.transitioning = False
            self._changed()
            self._log_component_change(name, target, reached, stopped)
            return reached

    def _log_component_change(self, name: str, target: State, reached: State, stopped: List[str]) -> None:
        deactivated = f"deactivated controller(s) {stopped}" if stopped else "no controller was using it"
        if reached != target:
            self.logger.error(f"hardware '{name}' did not reach {target.label}; it is {reached.label} (see the "
                              f"lines above); {deactivated}")
        elif target == State.FINALIZED:
            self.logger.warning(f"hardware '{name}' finalized: {deactivated}; its interfaces are gone until the "
                                "controller manager restarts (a finalized component cannot be configured again)")
        elif stopped:
            self.logger.warning(f"hardware '{name}' is now {target.label}: {deactivated}; to resume, set it active "
                                f"again and activate them (switch_controllers --activate {' '.join(stopped)})")
        else:
            self.logger.info(f"hardware '{name}' is now {target.label}")

    def _wait_for_cycle(self, timeout: float = 1.0) -> None:
        """With a running loop: return once the cycle in progress (if any) has finished."""
        if not self.loop_running:
            return
        start, deadline = self._cycle, _time.monotonic() + timeout
        while self._cycle == start and self.loop_running and _time.monotonic() < deadline:
            _time.sleep(0.0005)

    def _deactivate_users(self, component: str, commands_only: bool) -> List[str]:
        """Deactivate the active controllers using `component`; returns their names."""
        names = [s.name for s in self._users_of(component, commands_only)]
        if names:
            self.switch_controller([], names, switching.BEST_EFFORT)
        return names

    def _users_of(self, component: str, commands_only: bool = False) -> List[ControllerSpec]:
        owner = self.rm.interface_owner
        return [s for s in list(self.controllers.values()) if s.state == State.ACTIVE
                and any(owner.get(i) == component
                        for i in (s.command_names if commands_only else (*s.command_names, *s.state_names)))]

    # ---- controller lifecycle (executor thread) -------------------------------------------
    def load_controller(self, name: str, type_name: str = "", params: Optional[dict] = None) -> ControllerSpec:
        with self.lock:
            if name in self.controllers:
                raise ControllerError(f"controller '{name}' is already loaded")
            config = self.controller_config.get(name, {})
            type_name = type_name or config.get("type", "")
            if not type_name:
                raise ControllerError(f"controller '{name}': no type (set '{name}.type' in the manager's parameters)")
            try:
                cls = load_class(CONTROLLER_GROUP, type_name)
            except PluginError as error:
                raise ControllerError(f"controller '{name}': {error}") from None
            controller: ControllerInterface = cls()
            node = self.node_factory(name) if self.node_factory is not None else None
            logger = node.get_logger() if node is not None else logging.getLogger(name)
            try:
                controller.robot_description = self.robot_description
                result = controller.init(name, node, logger, self.update_rate)
            except Exception as error:  # noqa: BLE001
                logger.error(f"controller '{name}': on_init raised {error!r}")
                result = CallbackReturn.ERROR
            if result != CallbackReturn.SUCCESS:
                self._destroy_node(node)
                raise ControllerError(f"controller '{name}' ({type_name}): on_init failed")
            controller.lifecycle_state = State.UNCONFIGURED
            spec = ControllerSpec(name, type_name, controller, list(config.get("fallback_controllers", [])), params)
            self.controllers[name] = spec
            self._changed()
            return spec

    def configure_controller(self, name: str) -> None:
        with self.lock:
            spec = self._get(name)
            if spec.state == State.INACTIVE:
                self.cleanup_controller(name)
            if spec.state != State.UNCONFIGURED:
                raise ControllerError(f"controller '{name}' is {spec.state.label}; only an unconfigured "
                                      "or inactive controller can be configured")
            try:
                spec.c.load_params(spec.param_values)
            except ParameterError as error:
                raise ControllerError(f"controller '{name}': {error}") from None
            if self._call(spec, "on_configure", State.UNCONFIGURED) != CallbackReturn.SUCCESS:
                raise ControllerError(f"controller '{name}': on_configure failed")
            spec.resolve_interfaces(self.rm.command_interfaces, self.rm.state_interfaces)
            missing = [i for i in spec.command_names if i not in self.rm.command_interfaces]
            missing_states = [i for i in spec.state_names if i not in self.rm.state_interfaces]
            if missing or missing_states:
                self._call(spec, "on_cleanup", State.INACTIVE)
                what = "; ".join(filter(None, [
                    f"unknown command interface(s) {missing}" if missing else "",
                    f"unknown state interface(s) {missing_states}" if missing_states else ""]))
                raise ControllerError(f"controller '{name}': {what}")
            spec.set_rate(self.update_rate, self.logger)
            if spec.c.is_chainable():
                self.rm.add_controller_interfaces(name, spec.c.export_reference_interfaces(),
                                                  spec.c.export_state_interfaces(), State.INACTIVE)
            spec.state = State.INACTIVE
            self._changed()

    def cleanup_controller(self, name: str) -> None:
        with self.lock:
            spec = self._get(name)
            if spec.state != State.INACTIVE:
                raise ControllerError(f"controller '{name}' is {spec.state.label}; only an inactive "
                                      "controller can be cleaned up")
            if self._call(spec, "on_cleanup", State.INACTIVE) != CallbackReturn.SUCCESS:
                raise ControllerError(f"controller '{name}': on_cleanup failed")
            self.rm.remove_controller_interfaces(name)
            spec.state = State.UNCONFIGURED
            self._changed()

    def unload_controller(self, name: str) -> None:
        with self.lock:
            spec = self._get(name)
            if spec.state == State.ACTIVE:
                raise ControllerError(f"controller '{name}' is active; deactivate it before unloading")
            if spec.state == State.INACTIVE:
                self.cleanup_controller(name)
            self._call(spec, "on_shutdown", spec.state)
            spec.state = State.FINALIZED
            del self.controllers[name]
            self._destroy_node(spec.c.get_node())
            self._changed()

    def _get(self, name: str) -> ControllerSpec:
        spec = self.controllers.get(name)
        if spec is None:
            raise ControllerError(f"controller '{name}' is not loaded")
        return spec

    def _call(self, spec: ControllerSpec, hook: str, previous: State) -> CallbackReturn:
        try:
            return getattr(spec.c, hook)(previous)
        except Exception as error:  # noqa: BLE001 - a controller bug is a failed transition
            self.logger.error(f"controller '{spec.name}': {hook} raised {error!r}")
            return CallbackReturn.ERROR

    def _destroy_node(self, node) -> None:
        if node is not None:
            try:
                self.release_node(node)
            except Exception:  # noqa: BLE001 - best effort
                pass

    def _changed(self) -> None:
        self.version += 1
        self.on_change()

    # ---- switching ----------------------------------------------------------------------------
    def switch_controller(self, activate: List[str], deactivate: List[str], strictness: int = switching.STRICT,
                          activate_asap: bool = True, timeout: float = 0.0) -> switching.SwitchPlan:
        """Plan, then have the loop apply it between cycles. Raises SwitchError.

        strictness: 1 BEST_EFFORT, 2 STRICT, 3 AUTO (adds the chained controllers needed),
        4 FORCE_AUTO (also deactivates whoever holds the interfaces); 0 -> BEST_EFFORT, as
        ros2_control. timeout: seconds for the loop to apply it (0: as long as the loop runs).
        """
        with self.lock:
            plan = switching.plan_switch(self, list(activate), list(deactivate),
                                         strictness or switching.BEST_EFFORT, activate_asap)
            if plan.empty:
                return plan
            if not self.loop_running:
                self._apply(plan, same_cycle=True)
                return self._check_activated(plan, strictness)
            self._switch_done.clear()
            self._pending = plan
            deadline = _time.monotonic() + timeout if timeout > 0 else None
            while not self._switch_done.wait(0.05):
                expired = deadline is not None and _time.monotonic() > deadline
                if expired or not self.loop_running:
                    with self._handoff:  # withdraw it unless the loop has picked it up
                        withdrawn = self._pending is plan
                        if withdrawn:
                            self._pending = None
                    if withdrawn:
                        raise switching.SwitchError(
                            f"switch not performed within {timeout:g} s (loop busy or stopped)")
                # picked up: the loop finishes it within a cycle or two
            return self._check_activated(plan, strictness)

    def _check_activated(self, plan: switching.SwitchPlan, strictness: int) -> switching.SwitchPlan:
        """A controller whose on_activate failed (it stays inactive) fails a STRICT switch."""
        failed = [s.name for s in plan.activate if s.state != State.ACTIVE]
        if failed:
            message = f"controller(s) {failed} failed to activate (on_activate failed; see the log)"
            if strictness != switching.BEST_EFFORT and strictness:
                raise switching.SwitchError(message)
            plan.messages.append(message)
        return plan

    def _apply(self, plan: switching.SwitchPlan, same_cycle: bool) -> None:
        times, clock = self.execution_time, _time.monotonic
        t0 = clock()
        switching.apply_deactivations(self, plan)
        t1 = clock()
        switching.perform_command_mode_switch(self, plan)
        t2 = clock()
        times.deactivation_time = (t1 - t0) * 1e6
        times.switch_perform_mode_time = (t2 - t1) * 1e6
        if plan.activate_asap or same_cycle or not (plan.start_interfaces or plan.stop_interfaces):
            switching.apply_activations(self, plan)
            times.activation_time = (clock() - t2) * 1e6
        else:  # let the hardware read once in its new mode before the controllers start
            self._pending_activations = plan
        self._reorder()
        times.switch_time = (clock() - t0) * 1e6

    def _reorder(self) -> None:
        """Active controllers in chain order: a controller runs before the ones it commands.

        Runs in both threads (switch in the loop, fallback); dicts are copied with list()
        (atomic under the GIL) because the executor may load a controller meanwhile."""
        active = [s for s in list(self.controllers.values()) if s.state == State.ACTIVE]
        owner = self.rm.interface_owner
        ordered: List[ControllerSpec] = []
        placed = set()
        while len(ordered) < len(active):
            progress = False
            for spec in active:
                if spec.name in placed:
                    continue
                feeders = [s for s in active if s.name not in placed and s is not spec
                           and any(owner.get(i) == spec.name for i in s.command_names)]
                if not feeders:
                    ordered.append(spec)
                    placed.add(spec.name)
                    progress = True
            if not progress:  # a cycle: keep the remaining order
                ordered.extend(s for s in active if s.name not in placed)
                break
        self.ordered = ordered
        self._changed()

    # ---- the cycle (loop thread) ------------------------------------------------------------
    def request_stats_reset(self) -> None:
        """Have the loop restart the statistics windows at its next cycle (thread-safe)."""
        self._reset_stats = True

    def all_stats(self):
        """Every statistics window the loop updates (the manager's, controllers', hardware's)."""
        yield self.loop_stats.execution_time
        yield self.loop_stats.periodicity
        yield from (self.read_time, self.update_time, self.write_time)
        for spec in list(self.controllers.values()):
            if spec.async_handler is None:  # an async worker updates its own: left alone
                yield spec.stats.execution_time
                yield spec.stats.periodicity
        for comp in list(self.rm.components.values()):
            if comp.async_handler is None:
                yield from (comp.read_stats.execution_time, comp.read_stats.periodicity,
                            comp.write_stats.execution_time, comp.write_stats.periodicity)

    def cycle(self, time: float, period: float) -> None:
        """One read -> update -> write at `time` (s); `period` (s) since the previous cycle."""
        start = _time.monotonic()
        times = self.execution_time
        times.new_cycle()
        if self._reset_stats:
            self._reset_stats = False
            for stats in self.all_stats():
                stats.reset()
        plan = None
        if self._pending is not None:
            with self._handoff:
                plan, self._pending = self._pending, None
        if plan is not None:
            try:
                self._apply(plan, same_cycle=False)
            finally:
                if self._pending_activations is None:
                    self._switch_done.set()
        elif self._pending_activations is not None:
            plan, self._pending_activations = self._pending_activations, None
            try:
                switching.apply_activations(self, plan)
                self._reorder()
                times.activation_time = times.switch_time = (_time.monotonic() - start) * 1e6
            finally:
                self._switch_done.set()  # the caller returns once activations are done too
        failed = self._failed
        self.rm.read(time, period, self._cycle, failed)
        if failed:
            self._hardware_failed(failed)
        t_read = _time.monotonic()
        self._update(time, period)
        t_update = _time.monotonic()
        self.rm.write(time, period, self._cycle, failed)
        if failed:
            self._hardware_failed(failed)
        end = _time.monotonic()
        times.read_time = (t_read - start) * 1e6
        times.update_time = (t_update - t_read) * 1e6
        times.write_time = (end - t_update) * 1e6
        times.total_time = (end - start) * 1e6
        self.read_time.add(times.read_time)
        self.update_time.add(times.update_time)
        self.write_time.add(times.write_time)
        self.loop_stats.add(start, end)
        self._cycle += 1

    def stop_if_shut_down(self) -> bool:
        """After an error in the loop: when the process is shutting down (a publish after Ctrl-C
        shut the context down), the end rather than a fault; the loop is told to stop."""
        if self.alive():
            return False
        self.stopping = True
        return True

    def _update(self, time: float, period: float) -> None:
        cycle, failures = self._cycle, self._failed_controllers
        for spec in self.ordered:
            if cycle % spec.divisor:
                continue
            try:
                result = spec.run(time, period * spec.divisor)
            except Exception as error:  # noqa: BLE001 - the loop survives a controller bug
                if self.stop_if_shut_down():
                    return
                self.throttle.error(spec.name, f"controller '{spec.name}': update raised {error!r}; deactivating")
                result = return_type.ERROR
            if result != return_type.OK:
                spec.update_errors += 1
                failures.append(spec)
        if failures:
            for spec in failures:
                self._fall_back(spec)
            failures.clear()

    def _fall_back(self, spec: ControllerSpec) -> None:
        """Loop thread: deactivate a failed controller and activate its fallback controllers."""
        if spec.state != State.ACTIVE:
            return
        self.throttle.error(f"{spec.name}.fallback", f"controller '{spec.name}' failed in update; "
                            f"deactivated, fallback controllers: {spec.fallback_controllers or 'none'}")
        switching.deactivate(self, spec)
        for name in spec.fallback_controllers:
            fallback = self.controllers.get(name)
            if fallback is not None and fallback.state == State.INACTIVE:
                switching.activate(self, fallback)
        self._reorder()

    def _hardware_failed(self, failed: List[str]) -> None:
        for name in failed:
            self.throttle.error(f"hw.{name}", f"hardware '{name}': read/write failed; deactivating its "
                                "controllers, component goes through on_error")
            for spec in self._users_of(name):
                switching.deactivate(self, spec)
            self.rm.handle_failure(name)
        failed.clear()
        self._reorder()

    def shutdown(self) -> None:
        with self.lock:
            for spec in list(self.controllers.values()):
                if spec.state == State.ACTIVE:
                    switching.deactivate(self, spec)
            self.ordered = []
            for name in list(self.controllers):
                self.unload_controller(name)
            self.rm.shutdown()
