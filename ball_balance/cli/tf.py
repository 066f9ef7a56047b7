"""`ros2py tf echo TARGET SOURCE` (like tf2_ros's tf2_echo): the transform, printed once per second."""
from __future__ import annotations

import math

from ball_balance.cli.errors import CliError
from ball_balance.cli.session import Session


def format_transform(transform, stamp_ns: int) -> str:
    from ball_balance.tf import quat_to_euler

    t, q = transform.translation, transform.rotation
    rpy = quat_to_euler(q)
    return "\n".join([
        f"At time {stamp_ns / 1e9:.9f}",
        f"- Translation: [{t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}]",
        f"- Rotation: in Quaternion (xyzw) [{q[0]:.3f}, {q[1]:.3f}, {q[2]:.3f}, {q[3]:.3f}]",
        f"- Rotation: in RPY (radian) [{rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}]",
        "- Rotation: in RPY (degree) [" + ", ".join(f"{math.degrees(a):.3f}" for a in rpy) + "]",
    ])


def cmd_echo(args) -> int:
    from ball_balance.tf import TransformException
    from ball_balance.tf.ros import Buffer, TransformListener

    with Session(args.spin_time) as session:
        buffer = Buffer()
        TransformListener(buffer, session.node)
        printed = 0
        while args.count is None or printed < args.count:
            session.spin_until(lambda: buffer.core.can_transform(args.target_frame, args.source_frame),
                               args.timeout)
            try:
                transform, stamp_ns = buffer.core.lookup_transform(args.target_frame, args.source_frame)
            except TransformException as error:
                raise CliError(f"cannot transform [{args.source_frame}] into [{args.target_frame}] "
                               f"(waited {args.timeout:.1f} s): {error}") from None
            print(format_transform(transform, stamp_ns), flush=True)
            printed += 1
            if args.count is None or printed < args.count:
                session.spin_for(1.0 / args.rate)
    return 0
