"""Parse the `<ros2_control>` blocks of a robot description into HardwareInfo.

Follows ros2_control's component_parser: `<ros2_control name type is_async rw_rate>`,
`<hardware><plugin/><param name=""/><properties><async .../></properties></hardware>`,
`<joint>`/`<sensor>`/`<gpio>` with `<command_interface>`/`<state_interface>` whose `<param>`
children `min`, `max`, `initial_value` are understood. Joint limits come from the URDF
`<joint><limit lower upper velocity effort/>` (continuous joints have no position limits),
narrowed by the command interface min/max params; `<limits enable="false"/>` in a joint or
one of its command interfaces turns enforcement off there, as in ros2_control; an
`acceleration` command interface's max (or |min|) param sets the acceleration limit.
A revolute or prismatic joint of a `<ros2_control>` block with no `<limit>` in the URDF is
refused (`require_limits=False` accepts it): nothing could keep its commands in range.
Any problem raises DescriptionError with one line naming the offending element.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from typing import Dict, List, Tuple

from .types import AsyncParams, ComponentInfo, HardwareInfo, InterfaceInfo, JointLimits


class DescriptionError(ValueError):
    """The robot description cannot be used (malformed XML, missing plugin, bad number)."""


KINDS = ("system", "sensor", "actuator")


def parse_control_resources(urdf: str, require_limits: bool = True) -> List[HardwareInfo]:
    """All `<ros2_control>` blocks of `urdf`, in document order. require_limits: refuse a
    revolute/prismatic joint without `<limit>` (unless its limits are disabled in its block)."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as error:
        raise DescriptionError(f"robot description is not valid XML: {error}") from None
    blocks = root.findall(".//ros2_control")
    if root.tag == "ros2_control":
        blocks.insert(0, root)
    if not blocks:
        raise DescriptionError("robot description has no <ros2_control> tag")
    urdf_limits, unlimited = _urdf_joint_limits(root)
    infos = [_parse_block(block, urdf_limits) for block in blocks]
    if require_limits:
        for info in infos:
            for joint in info.joints:
                if joint.name in unlimited and info.limits[joint.name].enforced("position"):
                    raise DescriptionError(
                        f"joint '{joint.name}' ({unlimited[joint.name]}) has no <limit> in the URDF, so its commands "
                        "cannot be kept in range: add <limit lower=... upper=... velocity=... effort=.../>, or "
                        "<limits enable=\"false\"/> in its <ros2_control> <joint>, or set "
                        "allow_joints_without_limits")
    names = [info.name for info in infos]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise DescriptionError(f"duplicate <ros2_control name=...>: {', '.join(duplicates)}")
    return infos


def _parse_block(block: ET.Element, urdf_limits: Dict[str, JointLimits]) -> HardwareInfo:
    name = block.get("name")
    if not name:
        raise DescriptionError("<ros2_control> without a 'name' attribute")
    kind = (block.get("type") or "").lower()
    if kind not in KINDS:
        raise DescriptionError(f"<ros2_control name='{name}'>: type must be one of {KINDS}, got {kind!r}")
    hardware = block.find("hardware")
    plugin = hardware.findtext("plugin", "").strip() if hardware is not None else ""
    if not plugin:
        raise DescriptionError(f"<ros2_control name='{name}'>: missing <hardware><plugin>")
    info = HardwareInfo(name=name, type=kind, hardware_plugin_name=plugin,
                        hardware_parameters=_params(hardware, name),
                        is_async=_bool(block.get("is_async", "false"), f"{name} is_async"),
                        rw_rate=int(_number(block.get("rw_rate", "0"), f"{name} rw_rate")),
                        original_xml=ET.tostring(block, encoding="unicode"))
    props = hardware.find("properties/async") if hardware is not None else None
    if props is not None:
        info.async_params = AsyncParams(
            thread_priority=int(_number(props.get("thread_priority", "50"), f"{name} thread_priority")),
            affinity=[int(c) for c in props.get("affinity", "").replace(",", " ").split()],
            scheduling_policy=props.get("scheduling_policy", "synchronized"),
            print_warnings=_bool(props.get("print_warnings", "true"), f"{name} print_warnings"))
        if info.async_params.scheduling_policy not in ("synchronized", "detached"):
            raise DescriptionError(f"<ros2_control name='{name}'>: scheduling_policy must be "
                                   f"synchronized or detached, got {info.async_params.scheduling_policy!r}")
    disabled: Dict[str, List[str]] = {}  # joint -> interfaces with <limits enable="false"/> ("*": all)
    for tag, target in (("joint", info.joints), ("sensor", info.sensors), ("gpio", info.gpios)):
        for element in block.findall(tag):
            target.append(_component(element, tag, name))
            if tag == "joint":
                disabled[element.get("name")] = _limits_disabled(element)
    for joint in info.joints:
        limits = replace(urdf_limits.get(joint.name, JointLimits()), disabled=frozenset(disabled.get(joint.name, ())))
        for itf in joint.command_interfaces:
            if itf.name == "position":
                if itf.min is not None:
                    limits.min_position = max(limits.min_position, itf.min)
                if itf.max is not None:
                    limits.max_position = min(limits.max_position, itf.max)
            elif itf.name == "velocity" and itf.max is not None:
                limits.max_velocity = min(limits.max_velocity, abs(itf.max))
            elif itf.name == "acceleration" and (itf.max is not None or itf.min is not None):
                given = itf.max if itf.max is not None else itf.min
                limits.max_acceleration = min(limits.max_acceleration, abs(given))
        info.limits[joint.name] = limits
    return info


def _limits_disabled(joint: ET.Element) -> List[str]:
    """ros2_control's `<limits enable="false"/>` on a joint ("*") or on its command interfaces."""
    def off(element) -> bool:
        limits = element.find("limits")
        return limits is not None and limits.get("enable", "true").strip().lower() in ("false", "0")
    names = ["*"] if off(joint) else []
    return names + [itf.get("name", "") for itf in joint.findall("command_interface") if off(itf)]


def _component(element: ET.Element, tag: str, block: str) -> ComponentInfo:
    cname = element.get("name")
    if not cname:
        raise DescriptionError(f"<ros2_control name='{block}'>: <{tag}> without a 'name'")
    comp = ComponentInfo(name=cname, type=tag, parameters=_params(element, f"{block}/{cname}"))
    for itf_tag, target in (("command_interface", comp.command_interfaces),
                            ("state_interface", comp.state_interfaces)):
        for itf in element.findall(itf_tag):
            iname = itf.get("name")
            if not iname:
                raise DescriptionError(f"<{tag} name='{cname}'>: <{itf_tag}> without a 'name'")
            params = _params(itf, f"{cname}/{iname}")
            where = f"<{tag} name='{cname}'> {itf_tag} '{iname}'"
            target.append(InterfaceInfo(
                name=iname,
                min=_number(params["min"], f"{where} min") if "min" in params else None,
                max=_number(params["max"], f"{where} max") if "max" in params else None,
                initial_value=(_number(params["initial_value"], f"{where} initial_value")
                               if "initial_value" in params else None),
                data_type=itf.get("data_type", "double"), parameters=params))
    return comp


def _params(element, where: str) -> Dict[str, str]:
    params: Dict[str, str] = {}
    if element is None:
        return params
    for p in element.findall("param"):
        pname = p.get("name")
        if not pname:
            raise DescriptionError(f"{where}: <param> without a 'name'")
        params[pname] = (p.text or "").strip()
    return params


def _urdf_joint_limits(root: ET.Element) -> Tuple[Dict[str, JointLimits], Dict[str, str]]:
    """URDF `<joint>` limits by joint name, and the revolute/prismatic joints without `<limit>`
    (name -> type)."""
    limits: Dict[str, JointLimits] = {}
    unlimited: Dict[str, str] = {}
    for joint in root.iter("joint"):
        name, limit, kind = joint.get("name"), joint.find("limit"), joint.get("type")
        if name and limit is None and kind in ("revolute", "prismatic"):
            unlimited[name] = kind
        if not name or limit is None or kind is None:
            continue
        lim = JointLimits()
        if joint.get("type") in ("revolute", "prismatic"):
            if limit.get("lower") is not None:
                lim.min_position = _number(limit.get("lower"), f"joint '{name}' limit lower")
            if limit.get("upper") is not None:
                lim.max_position = _number(limit.get("upper"), f"joint '{name}' limit upper")
        if limit.get("velocity") is not None:
            lim.max_velocity = abs(_number(limit.get("velocity"), f"joint '{name}' limit velocity"))
        if limit.get("effort") is not None:
            lim.max_effort = abs(_number(limit.get("effort"), f"joint '{name}' limit effort"))
        limits[name] = lim
    return limits, unlimited


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise DescriptionError(f"{where}: {text!r} is not a number") from None
    if math.isnan(value):
        raise DescriptionError(f"{where}: NaN is not allowed")
    return value


def _bool(text: str, where: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("true", "1"):
        return True
    if lowered in ("false", "0"):
        return False
    raise DescriptionError(f"{where}: {text!r} is not true/false")
