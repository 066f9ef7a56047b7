"""Our pluginlib: plugin classes found through Python entry points.

Groups (declared in a package's setup.py entry_points, name = the plugin string):
  controller_manager_py.hardware     e.g. `mock_components/GenericSystem`
  controller_manager_py.controllers  e.g. `joint_state_broadcaster/JointStateBroadcaster`
Our own plugins are declared in this package's setup.py (HARDWARE / CONTROLLERS); any other
installed package adds its own the same way (README.md, "Plugins from another package").
Rebuild (colcon) after adding one. A `module.path:ClassName` string is accepted as well
(tests, quick experiments).
"""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import List

HARDWARE_GROUP = "controller_manager_py.hardware"
CONTROLLER_GROUP = "controller_manager_py.controllers"

class PluginError(LookupError):
    """No plugin of that name in the group (the message lists the known ones)."""


def available(group: str) -> List[str]:
    return sorted({ep.name for ep in entry_points(group=group)})


def load_class(group: str, name: str):
    """The class registered as `name` in `group` (entry point, built-in, or module:Class)."""
    for ep in entry_points(group=group):
        if ep.name == name:
            try:
                return ep.load()
            except (ImportError, AttributeError) as error:
                raise PluginError(f"plugin '{name}' cannot be imported: {error}") from None
    if ":" not in name:
        kind = "hardware" if group == HARDWARE_GROUP else "controller"
        raise PluginError(f"unknown {kind} plugin '{name}' (known: {', '.join(available(group)) or 'none'})")
    module, _, attr = name.partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as error:
        raise PluginError(f"plugin '{name}' cannot be imported: {error}") from None
