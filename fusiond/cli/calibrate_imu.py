"""`fusiond calibrate-imu`: a static IMU's noise, from Zenoh or a bag, printed as the config lines to paste.

It picks the configured IMUs by their config class: the command is about the IMU itself."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EXIT_USAGE, add_daemon_client_arguments, load_config, non_negative, positive
from .tool_session import tool_session

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=positive, default=60.0, help="seconds to record (default 60)")
    p.add_argument("--bag", help="read the IMU from this bag instead of Zenoh")
    p.add_argument("--start", type=non_negative, default=0.0, help="with --bag: skip the first S seconds")
    add_daemon_client_arguments(p, reads="the IMU sensor: key, encoding, extrinsic_rpy",
                                key="the IMU without a config: its Zenoh key (default imu/data, ROS 2 CDR), or with "
                                    "--bag its topic without the leading slash (the wheels then unread: a recording "
                                    "that moved is told by the IMU alone)")
    p.add_argument("--sensor", help="which imu sensor of the config (default: the first)")


def run(args: argparse.Namespace) -> int:
    from ..calibrate import calibrate, record_imu
    from ..config import ImuSensor
    from ..core.sensors.registry import kind_of

    if args.bag and not args.config and not args.key:
        print("fusiond: calibrate-imu --bag needs --config or --key (which topic is the IMU)", file=sys.stderr)
        return EXIT_USAGE
    cfg = load_config(args.config) if args.config else None
    imus = [s for s in cfg.sensors if kind_of(s).inertial] if cfg else []
    if args.sensor:
        imus = [s for s in imus if s.name == args.sensor]
    if cfg is not None and not imus:
        print(f"fusiond: no imu sensor {args.sensor or ''} in {args.config}".replace("  ", " "), file=sys.stderr)
        return EXIT_USAGE
    imu = imus[0] if imus else ImuSensor(name="imu", key=args.key or "imu/data")
    odom_cfg = next((s for s in cfg.sensors if kind_of(s).drives_prediction), None) if cfg else None
    odom: list = []
    if args.bag:
        from ..replay.bag import BagError, did_you_mean, open_bag_samples

        try:
            with open_bag_samples([Path(args.bag)], [imu] + ([odom_cfg] if odom_cfg else [])) as bag:
                if imu.name in bag.missing:  # the odometry's topic is there, the IMU's is not
                    have = ", ".join(f"{t} [{m}]" for t, m in sorted(bag.bag_topics.items()))
                    print(f"fusiond: calibrate-imu: the IMU topic /{imu.key} (sensor {imu.name!r}) is not in "
                          f"{args.bag}{did_you_mean(imu.key, bag.bag_topics)}; the bag has: {have}", file=sys.stderr)
                    return EXIT_USAGE
                read = list(bag)
        except BagError as err:
            print(f"fusiond: {err}", file=sys.stderr)
            return EXIT_USAGE
        samples = [s for s in read if s.sensor == imu.name]
        if samples:
            t0 = min(s.stamp for s in samples) + args.start
            samples = [s for s in samples if t0 <= s.stamp <= t0 + args.duration]
            odom = [s for s in read if odom_cfg and s.sensor == odom_cfg.name and t0 <= s.stamp <= t0 + args.duration]
    else:
        _, session = tool_session(args)
        try:
            if odom_cfg is not None:
                samples, odom = record_imu(session, imu, args.duration, odom_cfg)
            else:
                samples = record_imu(session, imu, args.duration)
        finally:
            session.close()
        if not samples:  # nothing answered: say where it listened, not only that it got nothing
            print(f"fusiond: calibrate-imu: no IMU message on key {imu.key!r} ({imu.encoding}) in {args.duration:g} s; "
                  "is the IMU publishing there? (--key, or --config and --sensor, name it; --connect reaches its "
                  "router)", file=sys.stderr)
            return 1
    try:
        cal = calibrate(samples, imu, odom or None)
    except ValueError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return 1
    if cal.refuse:
        print(f"fusiond: calibrate-imu: the IMU was not static ({'; '.join(cal.motion)}); its spread would be "
              "motion, not noise. Record it standing still", file=sys.stderr)
        return 1
    if cal.motion:
        print(f"fusiond: WARNING: the recording may not be static ({'; '.join(cal.motion)}): the numbers "
              "below may overstate the noise", file=sys.stderr)
    print(cal.snippet(imu.name))
    return 0
