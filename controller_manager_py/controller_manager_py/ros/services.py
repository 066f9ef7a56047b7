"""The ros2_control services, names and controller_manager_msgs types exactly as upstream.

All run in the executor thread. List responses are rebuilt only when the manager's
`version` changed (a load, switch, fallback, hardware transition), so polling them every
100 ms costs a cached reply, and nothing here runs in or waits on the loop except
switch_controller (which waits for the loop to apply the switch between two cycles).
"""
from __future__ import annotations

from controller_manager_msgs import msg as cm_msg
from controller_manager_msgs import srv
from lifecycle_msgs.msg import State as StateMsg

from ..controller_interface.base import ChainableControllerInterface
from ..hardware_interface.types import State
from ..manager.controller_manager import ControllerError, ControllerManager
from ..manager.resource_manager import ResourceError
from ..manager.switching import SwitchError
from ..plugins import CONTROLLER_GROUP, PluginError, available, load_class

SERVICES = {
    "list_controllers": srv.ListControllers,
    "list_controller_types": srv.ListControllerTypes,
    "load_controller": srv.LoadController,
    "configure_controller": srv.ConfigureController,
    "switch_controller": srv.SwitchController,
    "unload_controller": srv.UnloadController,
    "cleanup_controller": srv.CleanupController,
    "list_hardware_components": srv.ListHardwareComponents,
    "list_hardware_interfaces": srv.ListHardwareInterfaces,
    "set_hardware_component_state": srv.SetHardwareComponentState,
}


def _base_class(type_name: str) -> str:
    try:
        chainable = issubclass(load_class(CONTROLLER_GROUP, type_name), ChainableControllerInterface)
    except PluginError:
        return "unknown"
    return f"controller_interface::{'Chainable' if chainable else ''}ControllerInterface"


def state_msg(state: State) -> StateMsg:
    return StateMsg(id=int(state), label=state.label)


class ControllerManagerServices:
    def __init__(self, node, cm: ControllerManager, type_of):
        """type_of(name) -> the controller's type from the manager's parameters ('' if unset)."""
        self.node, self.cm, self.type_of = node, cm, type_of
        self.logger = node.get_logger()
        self._cache = {}
        self.services = [node.create_service(t, f"~/{name}", self._guarded(name, getattr(self, f"on_{name}")))
                         for name, t in SERVICES.items()]

    def _guarded(self, name, callback):
        def call(request, response):
            try:
                return callback(request, response)
            except Exception as error:  # noqa: BLE001 - a bug must not take the manager down
                self.logger.error(f"{name}: unexpected {error!r}")
                if hasattr(response, "ok"):
                    response.ok = False
                return response
        return call

    def _cached(self, key, build):
        version = self.cm.version
        hit = self._cache.get(key)
        if hit is None or hit[0] != version:
            hit = (version, build())
            self._cache[key] = hit
        return hit[1]

    # ---- controllers -----------------------------------------------------------------------
    def on_list_controllers(self, request, response):
        response.controller = self._cached("controllers", self.controller_states)
        return response

    def controller_states(self):
        cm, owner = self.cm, self.cm.rm.interface_owner
        states = []
        for spec in list(cm.controllers.values()):
            chained_to = {}
            for itf in spec.command_names:
                target = owner.get(itf)
                if target in cm.controllers:
                    chained_to.setdefault(target, []).append(itf)
            c = spec.c
            states.append(cm_msg.ControllerState(
                name=spec.name, state=spec.state.label, type=spec.type, is_async=c.is_async,
                update_rate=spec.effective_rate if spec.state in (State.INACTIVE, State.ACTIVE) else 0,
                claimed_interfaces=list(spec.claimed), required_command_interfaces=list(spec.command_names),
                required_state_interfaces=list(spec.state_names), is_chainable=c.is_chainable(),
                is_chained=bool(getattr(c, "chained_mode", False)),
                exported_state_interfaces=[h.name for h in getattr(c, "exported_state_interfaces", [])],
                reference_interfaces=[h.name for h in getattr(c, "reference_interfaces", [])],
                chain_connections=[cm_msg.ChainConnection(name=n, reference_interfaces=refs)
                                   for n, refs in chained_to.items()]))
        return states

    def on_list_controller_types(self, request, response):
        types = available(CONTROLLER_GROUP)
        response.types = types
        response.base_classes = [_base_class(t) for t in types]
        return response

    def _do(self, what: str, action, response):
        """Run `action`; ok/message from its outcome. Never lets an exception kill the node."""
        try:
            result = action()
            response.ok = True
            message = "; ".join(getattr(result, "messages", []) or [])
        except (ControllerError, SwitchError, ResourceError) as error:
            self.logger.error(f"{what}: {error}")
            response.ok, message = False, str(error)
        except Exception as error:  # noqa: BLE001 - a bug must not take the manager down
            self.logger.error(f"{what}: unexpected {error!r}")
            response.ok, message = False, f"internal error: {error!r}"
        if hasattr(response, "message"):
            response.message = message or ("Switch successful" if what == "switch_controller" else "")
        return response

    def on_load_controller(self, request, response):
        return self._do("load_controller", lambda: self.cm.load_controller(
            request.name, self.type_of(request.name)), response)

    def on_configure_controller(self, request, response):
        return self._do("configure_controller", lambda: self.cm.configure_controller(request.name), response)

    def on_cleanup_controller(self, request, response):
        return self._do("cleanup_controller", lambda: self.cm.cleanup_controller(request.name), response)

    def on_unload_controller(self, request, response):
        return self._do("unload_controller", lambda: self.cm.unload_controller(request.name), response)

    def on_switch_controller(self, request, response):
        timeout = request.timeout.sec + request.timeout.nanosec * 1e-9
        return self._do("switch_controller", lambda: self.cm.switch_controller(
            list(request.activate_controllers), list(request.deactivate_controllers), request.strictness,
            request.activate_asap, timeout), response)

    # ---- hardware ----------------------------------------------------------------------------
    def _data_types(self):
        """'joint/interface' -> the URDF's data_type (ros2_control's default 'double'), per kind."""
        def build():
            types = {True: {}, False: {}}
            for comp in list(self.cm.rm.components.values()):
                for part in (*comp.info.joints, *comp.info.sensors, *comp.info.gpios):
                    for commands, infos in ((True, part.command_interfaces), (False, part.state_interfaces)):
                        for itf in infos:
                            types[commands][f"{part.name}/{itf.name}"] = itf.data_type or "double"
            return types
        return self._cached("data_types", build)

    def _interfaces(self, names, commands: bool):
        rm = self.cm.rm
        available_fn = rm.command_available if commands else rm.state_available
        data_types = self._data_types()[commands]  # controllers' exported interfaces: double
        return [cm_msg.HardwareInterface(name=n, data_type=data_types.get(n, "double"), is_available=available_fn(n),
                                         is_claimed=n in rm.claimed) for n in names]

    def on_list_hardware_components(self, request, response):
        def build():
            out = []
            for comp in list(self.cm.rm.components.values()):
                commands, states = self.cm.rm.interfaces_of(comp.name)
                out.append(cm_msg.HardwareComponentState(
                    name=comp.name, type=comp.kind, is_async=comp.info.is_async, rw_rate=comp.rw_rate,
                    class_type=comp.info.plugin, plugin_name=comp.info.plugin,
                    state=state_msg(comp.state), command_interfaces=self._interfaces(commands, True),
                    state_interfaces=self._interfaces(states, False)))
            return out
        response.component = self._cached("components", build)
        return response

    def on_list_hardware_interfaces(self, request, response):
        rm = self.cm.rm
        response.command_interfaces = self._cached(
            "commands", lambda: self._interfaces(sorted(rm.command_interfaces), True))
        response.state_interfaces = self._cached("states", lambda: self._interfaces(sorted(rm.state_interfaces), False))
        return response

    def on_set_hardware_component_state(self, request, response):
        target = request.target_state
        try:
            wanted = State(target.id) if target.id else State[target.label.upper()]
        except (ValueError, KeyError):
            self.logger.error(f"set_hardware_component_state: unknown target state {target.id} '{target.label}'")
            response.ok = False
            return response
        try:
            reached = self.cm.set_hardware_component_state(request.name, wanted)
            response.ok = reached == wanted
            response.state = state_msg(reached)
        except (ResourceError, ControllerError, SwitchError) as error:
            self.logger.error(f"set_hardware_component_state: {error}")
            response.ok = False
        return response

    def activity(self):
        """controller_manager_msgs/ControllerManagerActivity for ~/activity."""
        msg = cm_msg.ControllerManagerActivity()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.controllers = [cm_msg.NamedLifecycleState(name=s.name, state=state_msg(s.state))
                           for s in list(self.cm.controllers.values())]
        msg.hardware_components = [cm_msg.NamedLifecycleState(name=c.name, state=state_msg(c.state))
                                   for c in list(self.cm.rm.components.values())]
        return msg
