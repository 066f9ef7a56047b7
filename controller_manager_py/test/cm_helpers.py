"""Shared helpers: a manager on the mock UR arm with synthetic time, and test-only plugins."""
from __future__ import annotations

import threading
from pathlib import Path

from controller_manager_py.controller_interface import ControllerInterface
from controller_manager_py.hardware_interface import CallbackReturn, SystemInterface, return_type
from controller_manager_py.manager.controller_manager import ControllerManager

MOCK_UR = (Path(__file__).resolve().parent / "mock_ur.urdf").read_text()  # a 6-joint UR on GenericSystem
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
HOME = [0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, 1.5707963267948966, 0.0]


def make_manager(rate: int = 500, urdf: str = MOCK_UR, config=None) -> ControllerManager:
    cm = ControllerManager(rate, controller_config=config)
    cm.load_robot_description(urdf)
    return cm


def run(cm: ControllerManager, cycles: int, start: float = 0.0) -> float:
    """Run `cycles` cycles of synthetic time; returns the time after the last one."""
    period = 1.0 / cm.update_rate
    t = start
    for _ in range(cycles):
        t += period
        cm.cycle(t, period)
    return t


def spawn(cm: ControllerManager, name: str, type_name: str, params=None, activate: bool = True):
    cm.load_controller(name, type_name, params or {})
    cm.configure_controller(name)
    if activate:
        cm.switch_controller([name], [], 2)
    return cm.controllers[name].c


def positions(cm: ControllerManager):
    return [cm.rm.state_interfaces[f"{j}/position"].value for j in JOINTS]


class CountingController(ControllerInterface):
    """Counts updates; optionally sleeps, raises or returns ERROR on demand."""

    def on_configure(self, previous_state):
        self.calls, self.periods, self.sleep_s, self.fail, self.raise_error = 0, [], 0.0, False, False
        self.release = threading.Event()
        return CallbackReturn.SUCCESS

    def update(self, time, period):
        self.calls += 1
        self.periods.append(period)
        if self.sleep_s:
            self.release.wait(self.sleep_s)
        if self.raise_error:
            raise RuntimeError("boom")
        return return_type.ERROR if self.fail else return_type.OK


class FlakySystem(SystemInterface):
    """The mock's interfaces, but read() fails when `fail_read` is set."""

    fail_read = False

    def read(self, time, period):
        return return_type.ERROR if FlakySystem.fail_read else return_type.OK


class SimClockSystem(SystemInterface):
    """A mock that owns the clock: simulated time starts at 1000 s and advances 1 ms per read."""

    provides_clock = True

    def on_init(self, info):
        self.sim_time = 1000.0
        return super().on_init(info)

    def now(self):
        return self.sim_time

    def read(self, time, period):
        self.sim_time += 0.001
        return return_type.OK


class BlockingSystem(SystemInterface):
    """read() blocks 10 ms, like hardware whose read sets the pace."""

    def read(self, time, period):
        import time as _time
        _time.sleep(0.01)
        return return_type.OK


class RefusingController(CountingController):
    """on_activate fails (e.g. the device reports a fault)."""

    def on_activate(self, previous_state):
        return CallbackReturn.FAILURE
