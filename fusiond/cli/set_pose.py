"""`fusiond set-pose X Y [YAW]`: robot_localization's set_pose, asked of a running daemon over Zenoh."""

from __future__ import annotations

import argparse
import math
import sys

from .common import EXIT_UNHEALTHY, EXIT_USAGE, add_daemon_client_arguments
from .tool_session import in_namespace, tool_session

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("x", type=float, help="position x in the output frame, m")
    p.add_argument("y", type=float, help="position y, m")
    p.add_argument("yaw", type=float, nargs="?", default=0.0, help="heading, rad (default 0)")
    p.add_argument("--z", type=float, default=0.0, help="position z, m (default 0)")
    p.add_argument("--roll", type=float, default=0.0, help="rad (default 0)")
    p.add_argument("--pitch", type=float, default=0.0, help="rad (default 0)")
    p.add_argument("--stamp", type=float, default=0.0,
                   help="time the pose holds at, s (message time); default 0: the filter's current time")
    p.add_argument("--sigma", type=float, nargs=2, default=(0.0, 0.0), metavar=("POSITION_M", "ATTITUDE_RAD"),
                   help="standard deviations of the pose (default 0 0: exactly this pose)")
    add_daemon_client_arguments(p, reads="set_pose key", key="set_pose key (default: output.set_pose_key of the config)",
                                timeout=True)


def run(args: argparse.Namespace) -> int:
    """robot_localization's set_pose: re-initialise a running daemon's filter at a pose."""
    import msgspec

    from ..codecs import SetPoseMessage
    from ..estimator.rotation import from_rpy
    from ..transport.session import request_set_pose

    values = {"x": args.x, "y": args.y, "yaw": args.yaw, "--z": args.z, "--roll": args.roll, "--pitch": args.pitch,
              "--stamp": args.stamp, "--sigma POSITION_M": args.sigma[0], "--sigma ATTITUDE_RAD": args.sigma[1]}
    for name, value in values.items():  # refused here, before a session, rather than by the daemon (or not at all)
        if not math.isfinite(value):
            print(f"fusiond: set-pose {name} {value}: must be a finite number", file=sys.stderr)
            return EXIT_USAGE
        if value < 0.0 and name.startswith("--sigma"):  # squared, a typed sign would vanish unseen
            print(f"fusiond: set-pose {name} {value:g}: a standard deviation must not be negative", file=sys.stderr)
            return EXIT_USAGE
        if value < 0.0 and name == "--stamp":
            print(f"fusiond: set-pose --stamp {value:g}: must not be negative (0: the filter's current time)",
                  file=sys.stderr)
            return EXIT_USAGE
    pos_var, att_var = args.sigma[0] ** 2, args.sigma[1] ** 2
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = pos_var if i < 3 else att_var
    message = SetPoseMessage(stamp=args.stamp, position=(args.x, args.y, args.z),
                             orientation=from_rpy(args.roll, args.pitch, args.yaw), covariance=tuple(cov))
    cfg, session = tool_session(args, unreachable_exit=EXIT_UNHEALTHY)
    key = args.key or cfg.output.set_pose_key
    try:
        answers, errors = request_set_pose(session, key, msgspec.json.encode(message), args.timeout)
    finally:
        session.close()
    for raw in answers:
        print(raw.decode())
    for text in errors:
        print(f"fusiond: {text}", file=sys.stderr)
    if not answers and not errors:
        waited = f"within {args.timeout:g} s"  # an unserved query is asked again until then
        print(f"fusiond: no daemon answered on {key!r}{in_namespace(cfg)} {waited} (not running, or not allowed)",
              file=sys.stderr)
    return 0 if answers and not errors else EXIT_UNHEALTHY
