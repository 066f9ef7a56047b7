"""`ros2py service call`, printing as ros2cli does."""
from __future__ import annotations

import time

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session, valid_name


def cmd_call(args) -> int:
    from ball_balance.cli.messages import get_interface, parse_yaml_values, set_message_fields

    service = valid_name(args.service_name, "service")
    srv_cls = get_interface(args.service_type, default_kind="srv")
    if not hasattr(srv_cls, "Request"):
        raise CliError(f"'{args.service_type}' is not a service type (e.g. std_srvs/srv/Trigger)")
    values = parse_yaml_values(args.values, "request values")
    request = set_message_fields(srv_cls.Request(), values)  # bad values refused before the network
    with Session() as session:
        client = session.node.create_client(srv_cls, service)   # one client for every repeat
        if not session.spin_until(client.service_is_ready, 0.5):
            print("waiting for service to become available...", flush=True)
            session.wait_for_service(client, args.timeout)
        next_time = time.monotonic()
        while True:
            print(f"requester: making request: {request!r}\n", flush=True)
            print(f"response:\n{session.request(client, request, args.timeout)!r}\n", flush=True)
            if args.rate is None:
                return 0
            next_time += 1.0 / args.rate
            session.spin_for(max(0.0, next_time - time.monotonic()))
