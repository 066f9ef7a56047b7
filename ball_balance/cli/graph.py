"""`ros2py node list` and `ros2py service list`, printing as ros2cli does."""
from __future__ import annotations

from ball_balance.cli.session import Session, name_type_pairs, node_names, print_name_type_pairs


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
