"""`fusiond play BAG --config FILE`: a bag's sensor topics onto Zenoh as zenoh-bridge-ros2dds would publish
them, and what the daemon that received them reports it did not fuse."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EXIT_USAGE, add_daemon_client_arguments, load_config, non_negative, positive
from .tool_session import in_namespace, reached, tool_session

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    add_daemon_client_arguments(p, reads="sensors, keys", config_required=True)
    p.add_argument("--rate", type=non_negative, default=1.0,
                   help="pace relative to the recording (default 1: the recorded pace); 0 = as fast as possible, "
                        "which the daemon's fusion paces (play reports anything the daemon dropped)")
    p.add_argument("--duration", type=positive, help="play only the first S seconds of the bag")
    p.add_argument("--allow-missing", action="store_true",
                   help="play without a configured sensor whose topic is not in the bag (a warning); default: "
                        "that is an error naming the topic")
    p.add_argument("--listen", action="append", metavar="ENDPOINT", help="Zenoh endpoint to listen on (repeatable)")
    p.add_argument("--wait", type=non_negative, default=5.0,
                   help="wait up to S seconds for the config's daemon to answer on its health key before "
                        "playing, then play anyway (default 5; 0: do not wait)")
    p.set_defaults(default_log_level="info")


def run(args: argparse.Namespace) -> int:
    import signal
    import threading

    from ..replay.bag import BagError, open_bag_samples
    from ..replay.run import missing_topics
    from ..transport.player import play

    cfg = load_config(args.config, needs="play")
    try:  # the bag first: a file that is no bag is refused before a session is opened or a daemon awaited
        bag = open_bag_samples([Path(b) for b in args.bags], cfg.sensors)
    except BagError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    if bag.missing and not args.allow_missing:  # a misspelt key would play a bag the daemon never hears part of
        print(f"fusiond: {missing_topics(bag, cfg)}. Fix the key in the config, or pass --allow-missing to play "
              "without it", file=sys.stderr)
        bag.close()
        return EXIT_USAGE
    stop = threading.Event()
    try:
        cfg, session = tool_session(args, listen=args.listen)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        try:
            result = play(bag, cfg, session, rate=args.rate, duration=args.duration, wait_s=args.wait, stop=stop,
                          names=args.bags)
        finally:
            session.close()
    except BagError as err:  # a chunk that cannot be read halfway through
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        bag.close()
    per = " ".join(f"{k}={v}" for k, v in result.per_sensor.items())
    print(f"played {result.messages} messages ({per}), {result.bag_seconds:.3f} s of bag in {result.seconds:.3f} s"
          + (" (interrupted)" if result.interrupted else ""))
    if result.no_daemon:
        print(f"fusiond: no daemon answered on {cfg.output.health_key!r}{in_namespace(cfg)} within --wait "
              f"{args.wait:g} s ({reached(args, cfg)}): nothing sent is known to be fused (--wait 0 plays without "
              "asking)", file=sys.stderr)
        return 1
    if result.daemon_stopped:
        print(f"fusiond: the daemon stopped answering on {cfg.output.health_key!r}{in_namespace(cfg)} while this "
              f"played ({result.daemon_stopped}): what it was sent after that went nowhere", file=sys.stderr)
        return 1
    if result.daemon_restarted:
        print(f"fusiond: the daemon on {cfg.output.health_key!r}{in_namespace(cfg)} restarted while this played "
              f"(Zenoh id {result.daemon_restarted}): its counts started over, so what it fused of these samples is "
              "not known, and what was sent while it was down went nowhere (its log says whether it resumed: "
              "state_resumed)", file=sys.stderr)
        return 1
    if result.daemon_dropped:
        print(f"fusiond: the daemon dropped {result.daemon_dropped} of these samples, its input queue full "
              f"(health: queue.dropped): it did not keep up with --rate {args.rate:g}; play slower", file=sys.stderr)
    for name, why in result.unfused.items():
        counts = ", ".join(f"{n} {reason}" for reason, n in sorted(why.items()))
        print(f"fusiond: sensor {name!r}: {sum(why.values())} of {result.per_sensor[name]} samples sent were not "
              f"fused ({counts}; health: sensors.{name}.dropped_by_reason)", file=sys.stderr)
    return 1 if result.daemon_dropped or result.unfused else 0
