"""`ros2py action list|info|send_goal`, printing as ros2cli (ros2action, Jazzy) does.

    ros2py action list [-t] [-c]
    ros2py action info /scaled_joint_trajectory_controller/follow_joint_trajectory [-t] [-c]
    ros2py action send_goal /scaled_joint_trajectory_controller/follow_joint_trajectory \
        control_msgs/action/FollowJointTrajectory "{trajectory: {...}}" --feedback

send_goal waits for the server, sends the goal, prints feedback as it arrives (with
--feedback) and the result; Ctrl-C cancels the goal. Our extension: the exit code is 0 only
when the goal SUCCEEDED (1 when rejected, aborted or canceled), so scripts can rely on it.
"""
from __future__ import annotations

import importlib
import time
from typing import Dict, List, Tuple

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, is_hidden, node_names, valid_name

STATUS_NAMES = {0: "UNKNOWN", 1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING", 4: "SUCCEEDED", 5: "CANCELED",
                6: "ABORTED"}  # action_msgs/msg/GoalStatus


def get_action(type_name: str):
    """The Python class of an action type, e.g. 'control_msgs/action/FollowJointTrajectory'."""
    from ball_balance.cli.messages import split_type_name

    pkg, kind, name = split_type_name(type_name, "action")
    if kind != "action":
        raise CliError(f"'{type_name}' is not an action type (expected package/action/Type)")
    try:
        module = importlib.import_module(f"{pkg}.action")
    except ImportError:
        raise CliError(f"unknown action type '{type_name}': no interface package '{pkg}' with actions "
                       "is installed") from None
    cls = getattr(module, name, None)
    if not isinstance(cls, type) or not hasattr(cls, "Goal"):
        raise CliError(f"unknown action type '{type_name}': package '{pkg}' has no action '{name}'")
    return cls


def _actions(session: Session) -> List[Tuple[str, List[str]]]:
    from rclpy.action import get_action_names_and_types

    return sorted((n, t) for n, t in get_action_names_and_types(session.node) if not is_hidden(n))


def _endpoints(session: Session, action: str) -> Tuple[Dict[str, List[str]], Dict[str, List[str]]]:
    """({node: types} of the action's clients, {node: types} of its servers)."""
    from rclpy.action.graph import (
        get_action_client_names_and_types_by_node,
        get_action_server_names_and_types_by_node,
    )

    clients, servers = {}, {}
    for full in node_names(session, include_hidden=True):
        namespace, _, name = full.rpartition("/")
        for found, lookup in ((clients, get_action_client_names_and_types_by_node),
                              (servers, get_action_server_names_and_types_by_node)):
            try:
                pairs = lookup(session.node, name, namespace or "/")
            except Exception:  # noqa: BLE001 - the node left the graph meanwhile
                continue
            for action_name, types in pairs:
                if action_name == action:
                    found[full] = list(types)
    return clients, servers


def cmd_list(args) -> int:
    with Session() as session:
        start = time.monotonic()
        session.discover(args.spin_time)
        # a busy participant can answer after the graph looked settled: an empty list is
        # worth the rest of the spin time before it is believed
        session.spin_until(lambda: bool(_actions(session)), max(0.0, args.spin_time - (time.monotonic() - start)))
        pairs = _actions(session)
    if args.count_actions:
        print(len(pairs))
        return 0
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def cmd_info(args) -> int:
    action = valid_name(args.action_name, "action")
    with Session() as session:
        session.discover(args.spin_time)
        found = {}

        def known() -> bool:  # on a loaded machine, a node's endpoints can come late
            found["ends"] = _endpoints(session, action)
            return bool(found["ends"][1])  # the server (clients alone: wait the spin time for one)

        session.spin_until(known, args.spin_time, step_s=0.1)
        clients, servers = found["ends"]
    print(f"Action: {action}")  # an unknown action: no clients and no servers, as ros2 action info
    for label, found in (("Action clients", clients), ("Action servers", servers)):
        print(f"{label}: {len(found)}")
        if not args.count:
            for node, types in sorted(found.items()):
                print(f"    {node} [{', '.join(types)}]" if args.show_types else f"    {node}")
    return 0


def _indented(msg) -> str:
    from ball_balance.cli.messages import message_to_yaml

    text = message_to_yaml(msg, truncate_length=None).rstrip("\n")
    return "\n".join(f"    {line}" for line in text.splitlines()) if text else "    {}"


def cmd_send_goal(args) -> int:
    from rclpy.action import ActionClient

    from ball_balance.cli.messages import parse_yaml_values, set_message_fields

    action = valid_name(args.action_name, "action")
    action_cls = get_action(args.action_type)
    goal = set_message_fields(action_cls.Goal(), parse_yaml_values(args.goal, "goal values"))
    with Session(args.spin_time) as session:
        client = ActionClient(session.node, action_cls, action)
        print("Waiting for an action server to become available...", flush=True)
        if not session.spin_until(client.server_is_ready, args.server_timeout):
            raise CliError(f"no action server for '{action}' ({args.action_type}) within {args.server_timeout:.1f} s; "
                           "see `ros2py action list -t`")
        print(f"Sending goal:\n{_indented(goal)}\n", flush=True)

        def on_feedback(message) -> None:
            print(f"Feedback:\n{_indented(message.feedback)}\n", flush=True)

        sent = client.send_goal_async(goal, feedback_callback=on_feedback if args.feedback else None)
        if not session.spin_until(sent.done, args.server_timeout):
            raise CliError(f"the server of '{action}' did not answer the goal within {args.server_timeout:.1f} s")
        handle = sent.result()
        if not handle.accepted:
            print("Goal was rejected.")
            return 1
        print(f"Goal accepted with ID: {bytes(handle.goal_id.uuid).hex()}\n", flush=True)
        result = handle.get_result_async()
        try:
            session.spin_until(result.done, None)
        except KeyboardInterrupt:
            print("Canceling goal...", flush=True)
            cancel = handle.cancel_goal_async()
            session.spin_until(cancel.done, 5.0)
            if cancel.done() and cancel.result().goals_canceling:
                print("Goal canceled.")
            else:
                print("Failed to cancel goal.")
            return 1
        status = result.result().status
        print(f"Result:\n{_indented(result.result().result)}\n")
        print(f"Goal finished with status: {STATUS_NAMES.get(status, status)}")
        client.destroy()
    return 0 if status == 4 else 1
