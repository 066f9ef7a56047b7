"""`ros2py node list|info` and `ros2py service list`, printing as ros2cli does."""
from __future__ import annotations

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, full_node_name, name_type_pairs, node_names, print_name_type_pairs


def cmd_node_list(args) -> int:
    with Session() as session:
        session.discover(args.spin_time)
        names = node_names(session, include_hidden=args.all)
    if args.count_nodes:
        print(len(names))
        return 0
    for name in names:
        print(name)
    return 0


def cmd_service_list(args) -> int:
    with Session() as session:
        session.discover(args.spin_time)
        pairs = name_type_pairs(session.node.get_service_names_and_types(), args.include_hidden_services)
    return print_name_type_pairs(pairs, args.count_services, args.show_types)


def node_endpoints(session: Session, node_name: str, include_hidden: bool = False):
    """(section title, [(name, types)]) for `ros2 node info`, in ros2cli's order."""
    from rclpy.action.graph import get_action_client_names_and_types_by_node, get_action_server_names_and_types_by_node

    namespace, _, name = node_name.rpartition("/")
    namespace = namespace or "/"
    node = session.node
    sections = (
        ("Subscribers", node.get_subscriber_names_and_types_by_node(name, namespace)),
        ("Publishers", node.get_publisher_names_and_types_by_node(name, namespace)),
        ("Service Servers", node.get_service_names_and_types_by_node(name, namespace)),
        ("Service Clients", node.get_client_names_and_types_by_node(name, namespace)),
        ("Action Servers", get_action_server_names_and_types_by_node(node, name, namespace)),
        ("Action Clients", get_action_client_names_and_types_by_node(node, name, namespace)),
    )
    return [(title, name_type_pairs(pairs, include_hidden)) for title, pairs in sections]


def cmd_node_info(args) -> int:
    node_name = full_node_name(args.node_name)
    with Session() as session:
        session.discover(args.spin_time)
        if node_name not in node_names(session, include_hidden=True):
            raise CliError(f"Unable to find node '{node_name}' (see `ros2py node list`)")
        sections = node_endpoints(session, node_name, args.include_hidden)
    print(node_name)
    for title, pairs in sections:
        print(f"  {title}:")
        # as ros2cli: an empty section is one empty line
        print("\n".join(f"    {name}: {', '.join(types)}" for name, types in pairs))
    return 0
