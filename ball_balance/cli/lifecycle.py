"""`ros2py lifecycle nodes|get|list|set`, printing as ros2cli's `ros2 lifecycle` does.

`set` waits for the transition's answer (configure can take as long as the node's own waits);
when the answer is lost or late, it asks `get_state` (again while the node is in a transition
state or still in the start state, for up to --timeout or --spin-time more, the longer) before it
reports a failure: a transition that completed is reported as successful.
"""
from __future__ import annotations

import time

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, absolute_name
from ball_balance.operation import lifecycle as lc

GET_STATE_TYPE = "lifecycle_msgs/srv/GetState"


def _lifecycle_nodes(session: Session):
    session.discover(session.spin_time_s)
    return sorted(name[: -len("/get_state")] for name, types in session.node.get_service_names_and_types()
                  if name.endswith("/get_state") and GET_STATE_TYPE in types)


def _get_state(session: Session, node: str, timeout_s: float):
    from lifecycle_msgs.srv import GetState

    return session.call(GetState, f"{node}/get_state", GetState.Request(), timeout_s).current_state


def _transitions(session: Session, node: str, timeout_s: float, graph: bool = False):
    from lifecycle_msgs.srv import GetAvailableTransitions

    service = f"{node}/{'get_transition_graph' if graph else 'get_available_transitions'}"
    return list(session.call(GetAvailableTransitions, service, GetAvailableTransitions.Request(),
                             timeout_s).available_transitions)


class _NodeWarnings:
    """The warnings and errors a node logs on /rosout, from now on."""

    def __init__(self, session: Session, node: str):
        from rcl_interfaces.msg import Log

        self.logger = node.lstrip("/").replace("/", ".")
        self.lines = []
        self.level = Log.WARN
        session.node.create_subscription(Log, "/rosout", self.on_log, 100)

    def on_log(self, msg) -> None:
        if msg.name == self.logger and msg.level >= self.level:
            self.lines.append(msg.msg.splitlines()[0] if msg.msg else "")

    def latest(self) -> str:
        """': <the last one>', or '' (nothing logged, or not received)."""
        return f": {self.lines[-1]}" if self.lines and self.lines[-1] else ""


def cmd_nodes(args) -> int:
    with Session(args.spin_time) as session:
        for node in _lifecycle_nodes(session):
            print(node)
    return 0


def cmd_get(args) -> int:
    with Session(args.spin_time) as session:
        nodes = [absolute_name(args.node_name)] if args.node_name else _lifecycle_nodes(session)
        for node in nodes:
            state = _get_state(session, node, args.spin_time)
            print(f"{state.label} [{state.id}]" if args.node_name else f"{node}: {state.label} [{state.id}]")
    return 0


def _print_transitions(transitions) -> None:
    for t in transitions:
        print(f"- {t.transition.label} [{t.transition.id}]\n\tStart: {t.start_state.label}\n"
              f"\tGoal: {t.goal_state.label}")


def cmd_list(args) -> int:
    with Session(args.spin_time) as session:
        _print_transitions(_transitions(session, absolute_name(args.node_name), args.spin_time, args.all))
    return 0


def cmd_set(args) -> int:
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    node = absolute_name(args.node_name)
    with Session(args.spin_time) as session:
        reasons = _NodeWarnings(session, node)   # matched while the transitions are asked for
        transitions = _transitions(session, node, args.spin_time)
        wanted = [t for t in transitions
                  if t.transition.label == args.transition or str(t.transition.id) == args.transition]
        if not wanted:
            print("Unknown transition requested, available ones are:")
            for t in transitions:
                print(f"- {t.transition.label} [{t.transition.id}]")
            return 1
        chosen = wanted[0]
        start = chosen.start_state.id
        goal = next((t.goal for t in lc.TRANSITIONS if t.id == chosen.transition.id), None)
        request = ChangeState.Request(transition=Transition(id=chosen.transition.id, label=chosen.transition.label))
        try:
            ok = session.call(ChangeState, f"{node}/change_state", request, args.timeout).success
        except CliError as error:   # lost or late: what state did it reach (once it is not in transition)?
            # the request may still be on its way: the node gets --spin-time (or --timeout) more
            state = _get_state(session, node, args.spin_time).id
            deadline = time.monotonic() + max(args.timeout, args.spin_time)
            while (state not in lc.PRIMARY_STATES or state == start) and time.monotonic() < deadline:
                session.spin_for(0.2)
                state = _get_state(session, node, args.spin_time).id
            ok = state == goal and state != start
            if not ok:
                print(f"{error}; {node} is {lc.STATE_LABELS.get(state, state)}")
        if not ok:
            session.spin_for(0.2)   # the node logs why before it answers: let it arrive
    # ChangeState answers only success: a failure's reason is what the node logged meanwhile
    print("Transitioning successful" if ok else f"Transitioning failed{reasons.latest()}")
    return 0 if ok else 1
