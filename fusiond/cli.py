"""Command line: `fusiond run | play | replay | doctor | init | info | report | tune | monitor | health | set-pose |
calibrate-imu | bench | bench-latency`.

Each command imports what it needs when it runs, so `replay` does not pay for Zenoh
nor `run` for matplotlib.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

EXIT_USAGE = 2


def _load_config(path: str, needs: str = ""):
    """The config, or exit 2 with one line. ``needs``: what the command does with its sensors (a config
    without any is refused, naming that, instead of failing later on what it cannot find)."""
    from .config import ConfigError, load

    try:
        cfg = load(path)
    except ConfigError as err:
        print(f"fusiond: config error: {err}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    if needs and not cfg.sensors:
        print(f"fusiond: config error: {path}: no [[sensors]] configured: nothing to {needs}; add at least the "
              "odometry sensor (see config.toml)", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)
    return cfg


def _output_error(path: str, option: str, directory: bool = False) -> str | None:
    """Why an output path cannot be written (checked before a long replay, not after it), or None."""
    import os

    p = Path(path)
    if directory and p.exists() and not p.is_dir():
        return f"{option} {path}: names an existing file; --report writes a directory (index.html and images)"
    if not directory and p.is_dir():
        return f"{option} {path}: is a directory"
    if p.exists():
        return None if os.access(p, os.W_OK) else f"{option} {path}: not writable"
    parent = p.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f"{option} {path}: {parent} is a file, not a directory"
    return None if os.access(parent, os.W_OK) else f"{option} {path}: cannot create it ({parent} is not writable)"


def cmd_replay(args: argparse.Namespace) -> int:
    cfg = _load_config(args.config, needs="replay")
    for option, value, directory in (("--tum", args.tum, False), ("--diagnostics", args.diagnostics, False),
                                     ("--plot", args.plot, False), ("--report", args.report, True),
                                     ("--evaluation", args.evaluation, False)):
        problem = _output_error(value, option, directory) if value else None
        if problem:
            print(f"fusiond: {problem}", file=sys.stderr)
            return EXIT_USAGE
    for option, value in (("--rpe-s", args.rpe_s), ("--segment-gap", args.segment_gap)):
        if not 0.0 < value < float("inf"):  # a window or a gap of no length scores nothing meaningful
            print(f"fusiond: {option} {value:g}: must be a positive number of seconds", file=sys.stderr)
            return EXIT_USAGE
    if args.fuse_every < 1:
        print(f"fusiond: --fuse-every {args.fuse_every}: must be 1 (fuse every message) or more", file=sys.stderr)
        return EXIT_USAGE
    from .errors import ReplayError
    from .replay.run import replay, summary

    reference = args.reference
    fuse_every = args.fuse_every
    recorder = None
    if reference or fuse_every > 1:
        from .replay.evaluate import Recorder

        try:
            recorder = Recorder(cfg, fuse_every)
        except ReplayError as err:
            print(f"fusiond: {err}", file=sys.stderr)
            return EXIT_USAGE
        if recorder.absolute is None and fuse_every > 1:
            print("fusiond: --fuse-every needs a gps or absolute pose sensor in the config", file=sys.stderr)
            return EXIT_USAGE
        if not reference:  # score on the held-back messages of the absolute sensor themselves
            reference = cfg.sensor(recorder.absolute).key
    if not args.advice_budget_s >= 0.0:
        print(f"fusiond: --advice-budget-s {args.advice_budget_s:g}: must be 0 or a positive number of seconds",
              file=sys.stderr)
        return EXIT_USAGE
    doctor = not args.quiet or bool(args.plot or args.report)  # --quiet: no summary to judge for
    # the samples as fused, kept to replay the doctor's advice on (what --fuse-every left, in bag order)
    fused: list | None = [] if doctor and args.advice_budget_s > 0.0 else None
    records: list | None = [] if fused is not None else None  # ... and what it made of them
    through = recorder.filter if recorder is not None else None
    if fused is not None:
        through = _kept(fused, through)
    try:
        result = replay(
            [Path(p) for p in args.bags],
            cfg,
            tum=Path(args.tum) if args.tum else None,
            diagnostics=Path(args.diagnostics) if args.diagnostics else None,
            keep_trace=bool(args.plot or args.report),
            progress=not args.quiet,
            warn=lambda message: print(f"fusiond: warning: {message}", file=sys.stderr),
            doctor=doctor,
            through=through,
            records=records,
            allow_missing=args.allow_missing,
            smooth=args.smooth,
        )
        if fused:
            from .tune.advice import prove_advice

            result.proven = prove_advice(cfg, fused, result.verdicts(), args.advice_budget_s, records)
        evaluation = None
        if recorder is not None:
            from .replay.evaluate import evaluate

            evaluation = evaluate([Path(p) for p in args.bags], cfg, reference, result.trajectory, recorder,
                                  segment_gap_s=args.segment_gap, rpe_s=args.rpe_s,
                                  heading_known=result.heading_known, smoothed=result.smoothed)
    except ReplayError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    if evaluation is not None and args.evaluation:
        import msgspec

        Path(args.evaluation).parent.mkdir(parents=True, exist_ok=True)
        Path(args.evaluation).write_bytes(msgspec.json.format(msgspec.json.encode(evaluation)))
    evaluation_text = None
    if evaluation is not None:
        from .replay.evaluate import format_evaluation

        evaluation_text = format_evaluation(evaluation)
    title = ", ".join(Path(b).name for b in args.bags)
    if args.plot:
        from .replay.plot import plot_replay

        plot_replay(result, Path(args.plot), title=title)
    if args.report:
        from .replay.report import write_report

        index = write_report(result, Path(args.report), title, evaluation_text)
        if not args.quiet:
            print(f"report      {index}")
    if not args.quiet:
        print(summary(result))
    if evaluation_text is not None:
        print(evaluation_text)
    if result.final is None or result.poses == 0:
        return 1  # nothing fused, or nothing published (the summary says why)
    return 0


def _kept(into: list, through=None):
    """A replay ``through`` hook that appends every sample reaching the core to ``into`` (after ``through``)."""
    def keep(samples):
        for s in samples if through is None else through(samples):
            into.append(s)
            yield s
    return keep


def _as_replay(bags: list[str], config: str, *options: str) -> argparse.Namespace:
    """The replay command's own arguments for these bags and options, parsed by its own parser (every
    default as `fusiond replay` has it), so that `doctor` and `report` are that command, not a copy."""
    return build_parser().parse_args(["replay", "--config", config, *options, "--", *bags])


def cmd_doctor(args: argparse.Namespace) -> int:
    """`fusiond doctor BAG --config FILE`: `replay` with the doctor and no output files; prints the
    summary with the doctor's verdicts. Exit codes as replay's."""
    return cmd_replay(_as_replay(args.bags, args.config, "--advice-budget-s", repr(args.advice_budget_s),
                                 *(["--allow-missing"] if args.allow_missing else [])))


def cmd_init(args: argparse.Namespace) -> int:
    """`fusiond init BAG --out FILE`: a commented starting config from the bags (init_config.py), then the
    doctor's replay of it."""
    from .init_config import write_init

    code = write_init(args.bags, args.out, force=args.force)
    return code or cmd_replay(_as_replay(args.bags, args.out, "--advice-budget-s", "0"))


def cmd_info(args: argparse.Namespace) -> int:
    """`fusiond info BAG`: topics, types, counts, rates, stated covariances, what fusiond would use (bag_info.py)."""
    from .bag_info import print_info

    return print_info(args.bags)


def cmd_report(args: argparse.Namespace) -> int:
    """`fusiond report BAG --config FILE --out DIR`: `replay --report DIR`."""
    return cmd_replay(_as_replay(args.bags, args.config, "--report", args.out, "--advice-budget-s",
                                 repr(args.advice_budget_s), *(["--quiet"] if args.quiet else []),
                                 *(["--allow-missing"] if args.allow_missing else [])))


EXIT_UNHEALTHY = 1
_STATUS_RANK = {"failed": 0, "starting": 1, "degraded": 1, "ok": 2}


def cmd_tune(args: argparse.Namespace) -> int:
    """Fit the configured noise to the bags (fusiond/tune) and write the complete tuned config."""
    cfg = _load_config(args.config, needs="tune")
    problem = _output_error(args.out, "--out")
    if problem:
        print(f"fusiond: {problem}", file=sys.stderr)
        return EXIT_USAGE
    if not args.budget_s > 0.0:
        print(f"fusiond: --budget-s {args.budget_s:g}: must be a positive number of seconds", file=sys.stderr)
        return EXIT_USAGE
    from .errors import ConfigError, ReplayError
    from .tune import format_table, read_samples, select, tunable_params, tune, write

    keys = [k for part in args.keys for k in part.split(",")] if args.keys else None
    try:
        if keys is not None:
            select(tunable_params(cfg), keys)  # an unknown key fails before the bags are read
        samples = read_samples([Path(b) for b in args.bags], cfg,
                               warn=lambda message: print(f"fusiond: warning: {message}", file=sys.stderr),
                               allow_missing=args.allow_missing)
        result = tune(samples, cfg, keys, budget_s=args.budget_s, progress=not args.quiet)
    except (ConfigError, ReplayError) as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    bags = ", ".join(Path(b).name for b in args.bags)
    b, a = result.heldback_before, result.heldback_after
    held = f"; held-back -log L {b.neg_loglik:.1f} -> {a.neg_loglik:.1f}" if b is not None and a is not None else ""
    header = (f"fusiond tune of {bags} from {args.config}: {len(result.changed)} key(s) tuned{held}.\n"
              "Keys at their default are left out; config.toml documents them.")
    write(args.out, result.config, result.comments, header)
    print(format_table(result))
    print(f"tuned config {args.out}")
    return 0


def _zenoh_errors():
    from .config import ConfigError
    from .transport.session import SessionError

    return ConfigError, SessionError


def cmd_run(args: argparse.Namespace) -> int:
    cfg = _load_config(args.config, needs="subscribe to: the daemon would wait forever for input")
    if getattr(args, "no_multicast", False):
        import msgspec

        cfg = msgspec.structs.replace(cfg, zenoh=msgspec.structs.replace(cfg.zenoh, multicast_scouting=False))
    from .transport.daemon import run

    ConfigError, SessionError = _zenoh_errors()
    try:
        return run(cfg, base_dir=Path(args.config).resolve().parent)
    except ConfigError as err:
        print(f"fusiond: config error: {args.config}: {err}", file=sys.stderr)
        return EXIT_USAGE
    except SessionError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return 1


def cmd_play(args: argparse.Namespace) -> int:
    import signal
    import threading

    from .replay.bag import BagError, open_bag_samples
    from .transport.player import play

    cfg = _load_config(args.config, needs="play")
    try:  # the bag first: a file that is no bag is refused before a session is opened or a daemon awaited
        bag = open_bag_samples([Path(b) for b in args.bags], cfg.sensors)
    except BagError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    stop = threading.Event()
    try:
        cfg, session = _tool_session(args, listen=args.listen)
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
    if result.daemon_stopped:
        print(f"fusiond: the daemon stopped answering on {cfg.output.health_key!r}{_in_namespace(cfg)} while this "
              f"played ({result.daemon_stopped}): what it was sent after that went nowhere", file=sys.stderr)
        return 1
    if result.daemon_dropped:
        print(f"fusiond: the daemon dropped {result.daemon_dropped} of these samples, its input queue full "
              f"(health: queue.dropped): it did not keep up with --rate {args.rate:g}; play slower", file=sys.stderr)
    for name, why in result.unfused.items():
        counts = ", ".join(f"{n} {reason}" for reason, n in sorted(why.items()))
        print(f"fusiond: sensor {name!r}: {sum(why.values())} of {result.per_sensor[name]} samples sent were not "
              f"fused ({counts}; health: sensors.{name}.dropped_by_reason)", file=sys.stderr)
    return 1 if result.daemon_dropped or result.unfused else 0


def cmd_health(args: argparse.Namespace) -> int:
    import json

    from .transport.session import query_health

    cfg, session = _tool_session(args, unreachable_exit=EXIT_UNHEALTHY)
    key = args.key or cfg.output.health_key
    try:
        answers = query_health(session, key, args.timeout)
    finally:
        session.close()
    if not answers:
        print(f"fusiond: no health answer on {key!r}{_in_namespace(cfg)} within {args.timeout} s "
              f"({_reached(args, cfg)})", file=sys.stderr)
        return EXIT_UNHEALTHY
    worst = None
    for raw in answers:
        print(raw.decode())
        status = json.loads(raw).get("status")
        rank = _STATUS_RANK.get(status, -1)
        worst = rank if worst is None else min(worst, rank)
    return 0 if worst is not None and worst >= _STATUS_RANK[args.min_status] else EXIT_UNHEALTHY


def cmd_set_pose(args: argparse.Namespace) -> int:
    """robot_localization's set_pose: re-initialise a running daemon's filter at a pose."""
    import msgspec

    from .codecs import SetPoseMessage
    from .estimator.rotation import from_rpy
    from .transport.session import request_set_pose

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
    cfg, session = _tool_session(args, unreachable_exit=EXIT_UNHEALTHY)
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
        print(f"fusiond: no daemon answered on {key!r}{_in_namespace(cfg)} within {args.timeout} s (not running, "
              "or not allowed)", file=sys.stderr)
    return 0 if answers and not errors else EXIT_UNHEALTHY


def _tool_session(args: argparse.Namespace, listen: list[str] | None = None, unreachable_exit: int = 1):
    """A Zenoh session for a client tool (play, health, monitor, calibrate-imu) of the daemon that the
    config describes: its [zenoh] table if a config is given, --connect wins. Errors exit: a bad config
    with 2, a session that cannot open with ``unreachable_exit``."""
    from .config import Config
    from .transport.session import client_config, open_session

    config = getattr(args, "config", None)
    cfg = _load_config(config) if config else Config()
    ConfigError, SessionError = _zenoh_errors()
    from .config import check_endpoint

    for option, endpoints in (("--connect", getattr(args, "connect", None)), ("--listen", listen)):
        for ep in endpoints or []:
            try:
                check_endpoint(ep, option)
            except ConfigError as err:
                print(f"fusiond: {err}", file=sys.stderr)
                raise SystemExit(EXIT_USAGE) from None
    base = Path(config).resolve().parent if config else None
    zc = cfg.zenoh
    if getattr(args, "no_multicast", False):
        import msgspec

        zc = msgspec.structs.replace(zc, multicast_scouting=False)
    try:
        return cfg, open_session(client_config(zc, base_dir=base, connect=args.connect, listen=listen))
    except ConfigError as err:
        prefix = f"{config}: " if config else ""
        print(f"fusiond: config error: {prefix}{err}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    except SessionError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        raise SystemExit(unreachable_exit) from None


def _reached(args: argparse.Namespace, cfg) -> str:
    """Where a tool's session looked for the daemon, for a "no answer" line: an operator reads whether
    it dialled the wrong endpoint or had nothing to dial at all."""
    from .transport.session import client_endpoints

    endpoints = client_endpoints(cfg.zenoh, getattr(args, "connect", None))
    scouting = cfg.zenoh.multicast_scouting and not getattr(args, "no_multicast", False)
    if endpoints:
        return "dialled " + ", ".join(endpoints) + (" and scouted by multicast" if scouting else "")
    if scouting:
        return "scouted by multicast only: give --connect ENDPOINT to dial the daemon"
    return ("nothing to reach: no --connect, no [zenoh] connect or listen endpoint in the config, and multicast "
            "scouting off")


def _in_namespace(cfg) -> str:
    """How a tool's message names the robot it asked: its namespace (the key on the wire), if any."""
    ns = cfg.zenoh.namespace
    return f" in namespace {ns!r}" if ns else " (no namespace)"


def cmd_router(args: argparse.Namespace) -> int:
    from .transport.router import router_config, run_router

    ConfigError, SessionError = _zenoh_errors()
    from .config import check_endpoint

    listen = args.listen or ["tcp/0.0.0.0:7447"]
    try:
        for option, endpoints in (("--listen", listen), ("--connect", args.connect or [])):
            for ep in endpoints:
                check_endpoint(ep, option)
        conf = router_config(listen, args.connect or [], multicast_scouting=args.multicast)
        return run_router(conf, ready=lambda session: print(f"router {session.zid()} listening on "
                                                            f"{', '.join(listen)}", flush=True))
    except ConfigError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    except SessionError as err:
        print(f"fusiond: router: {err}", file=sys.stderr)
        return 1


def _add_router_parser(sub) -> None:
    ro = sub.add_parser("router", help="a Zenoh router for a fleet's daemons and monitors (as zenohd)")
    ro.add_argument("--listen", action="append", metavar="ENDPOINT", default=None,
                    help="endpoint to listen on (repeatable; default tcp/0.0.0.0:7447)")
    ro.add_argument("--connect", action="append", metavar="ENDPOINT", help="another router to connect to")
    ro.add_argument("--multicast", action="store_true", help="scout for and answer peers by multicast (off)")
    ro.set_defaults(func=cmd_router, default_log_level="info")


def cmd_monitor(args: argparse.Namespace) -> int:
    from . import monitor

    cfg, session = _tool_session(args)
    try:
        return monitor.run(session, timeout=args.timeout, duration=args.duration, as_json=args.json,
                           interval=args.interval, health_key=cfg.output.health_key,
                           diagnostics_key=cfg.output.diagnostics_key, window=cfg.filter.nis_window,
                           fleet=args.fleet, namespace=args.namespace or "", stale_s=args.stale)
    finally:
        session.close()


def cmd_calibrate_imu(args: argparse.Namespace) -> int:
    from .calibrate import calibrate, record_imu
    from .config import ImuSensor

    if args.bag and not args.config and not args.key:
        print("fusiond: calibrate-imu --bag needs --config or --key (which topic is the IMU)", file=sys.stderr)
        return EXIT_USAGE
    cfg = _load_config(args.config) if args.config else None
    imus = [s for s in cfg.sensors if isinstance(s, ImuSensor)] if cfg else []
    if args.sensor:
        imus = [s for s in imus if s.name == args.sensor]
    if cfg is not None and not imus:
        print(f"fusiond: no imu sensor {args.sensor or ''} in {args.config}".replace("  ", " "), file=sys.stderr)
        return EXIT_USAGE
    imu = imus[0] if imus else ImuSensor(name="imu", key=args.key or "imu/data")
    from .core.sensors.registry import kind_of

    odom_cfg = next((s for s in cfg.sensors if kind_of(s).drives_prediction), None) if cfg else None
    odom: list = []
    if args.bag:
        from .replay.bag import BagError, did_you_mean, open_bag_samples

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
        _, session = _tool_session(args)
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


# The source tree fusiond runs from (an editable install, a clone): `bench`'s defaults are found there,
# not beside the current directory.
REPO_ROOT = Path(__file__).resolve().parents[1]
BENCH_BAG = REPO_ROOT / "data" / "jackal_test2.bag"
BENCH_CONFIG = REPO_ROOT / "examples" / "jackal.toml"


def _bench_input_error(bag: Path, cfg) -> str | None:
    """Why ``bench`` cannot replay this bag with this config, as ``replay`` would refuse it (no odometry
    sensor, a file that is no bag, the odometry or world-frame topic not in it), or None."""
    from .core.sensors.registry import kind_of
    from .replay.bag import BagError, open_bag_samples
    from .replay.run import check_topics

    if not any(kind_of(s).drives_prediction for s in cfg.sensors):
        return "the config has no odometry sensor to replay the bag with (add an odom [[sensors]] table)"
    try:
        with open_bag_samples([bag], cfg.sensors) as opened:
            check_topics(opened, cfg, None)
    except BagError as err:
        return str(err)
    return None


def cmd_bench(args: argparse.Namespace) -> int:
    import msgspec

    from . import bench

    bag = Path(args.bag) if args.bag else BENCH_BAG
    config = args.config or str(BENCH_CONFIG)
    if bag.is_dir():  # bench.run replays a bag file only (it skips anything else): say so, not "no such bag"
        print(f"fusiond: bench: --bag {bag} is a directory (a ROS 2 bag?); bench takes one bag file, a ROS 1 .bag "
              "or a ROS 2 .mcap", file=sys.stderr)
        return EXIT_USAGE
    if not bag.is_file():
        default = "" if args.bag else " (the default, data/jackal_test2.bag of the source tree fusiond runs from)"
        print(f"fusiond: bench: no such bag {bag}{default}; give one with --bag", file=sys.stderr)
        return EXIT_USAGE
    cfg = _load_config(config)
    problem = _bench_input_error(bag, cfg)
    if problem:  # found now, not after a minute of estimator benchmarks
        print(f"fusiond: bench: {problem}", file=sys.stderr)
        return EXIT_USAGE
    result = bench.run(bag, Path(config), cfg, quick=args.quick)
    if args.latency:
        from .transport.bench_latency import run_bench

        # The daemon as `fusiond run` runs it: outputs batched, not express (transport/outputs.py); its CPU
        # is the target's. `bench-latency --express` measures the express variant.
        lat = run_bench(seconds=args.seconds, imu_hz=1000.0, odom_hz=100.0, express=False)
        flat: dict[str, float] = {}
        for k, v in msgspec.to_builtins(lat).items():
            if isinstance(v, dict):  # latency statistics: pose, raw_hop, ... -> pose_p50_us, ...
                flat.update({f"{k}_{sk}": sv for sk, sv in v.items() if isinstance(sv, (int, float))})
            elif isinstance(v, (int, float)):
                flat[k] = v
        result["latency"] = flat
        result["targets"] = bench.targets(result)  # with the daemon's CPU ratio now
    if args.json:
        print(msgspec.json.encode(result).decode())
    else:
        print(bench.format_table(result))
    return 0


def cmd_bench_latency(args: argparse.Namespace) -> int:
    from .transport.bench_latency import format_table, run_bench

    result = run_bench(seconds=args.seconds, imu_hz=args.imu_hz, odom_hz=args.odom_hz, express=args.express)
    if args.json:
        import msgspec

        print(msgspec.json.encode(result).decode())
    else:
        print(format_table(result))
    return 0


LOG_LEVELS = ["debug", "info", "warning", "error"]


def _version() -> str:
    """The installed distribution's version (pyproject.toml), read only when asked for."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fusiond")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


class _VersionAction(argparse.Action):
    """`fusiond --version`: "fusiond <version>" on stdout, exit 0 (argparse's own action would read the
    version when the parser is built, i.e. on every command)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(f"fusiond {_version()}")
        parser.exit(0)


def _number(text: str, *, zero: bool) -> float:
    """An option's number, finite and positive (or, with ``zero``, also 0): argparse's own error otherwise, so that
    a duration, timeout or rate of no meaning is refused before anything runs (not as a traceback later)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and (value >= 0.0 if zero else value > 0.0)):
        raise argparse.ArgumentTypeError(f"{text}: must be {'0 or more' if zero else 'a positive number'}")
    return value


def _positive(text: str) -> float:
    return _number(text, zero=False)


def _non_negative(text: str) -> float:
    return _number(text, zero=True)


# replay, doctor and report: how long the doctor's paste lines may be replayed before they are printed
ADVICE_BUDGET = dict(type=float, default=60.0, metavar="S",
                     help="replay each of the doctor's paste lines on the bags before printing it, for up to S "
                          "seconds (default 60; 0: print them unreplayed)")

# Every command that opens a Zenoh session takes --no-multicast, so that it can be typed on any of them. The
# latency benchmark's sessions (bench-latency, bench --latency) connect to each other on loopback and never
# scout (transport/bench_latency.py): for them the flag states what already holds.
BENCH_NO_MULTICAST = "do not scout for peers by multicast (always so: the benchmark's sessions are on loopback)"


ALLOW_MISSING = {"action": "store_true",
                 "help": "replay without a configured sensor whose topic is not in the bag (a warning); "
                         "default: that is an error naming the topic"}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fusiond", description="Wheel odometry + IMU EKF fusion over Eclipse Zenoh.")
    p.add_argument("--log-level", choices=LOG_LEVELS, help="default: info for run and play, warning otherwise")
    p.add_argument("--version", action=_VersionAction, help="print the version and exit")
    # --log-level also after the subcommand, and in each subcommand's help (SUPPRESS: an absent one does
    # not overwrite the value given before the subcommand)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--log-level", choices=LOG_LEVELS, default=argparse.SUPPRESS,
                        help="log level of the structlog lines on stderr (default: info for run and play, "
                             "warning otherwise)")
    sub = p.add_subparsers(dest="command", required=True)
    _add_parser = sub.add_parser
    sub.add_parser = lambda *a, **k: _add_parser(*a, parents=[common], **k)  # type: ignore[method-assign]

    r = sub.add_parser("replay", help="replay ROS 1/2 bags through the fusion core")
    r.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    r.add_argument("--config", required=True, help="TOML config (see config.toml)")
    r.add_argument("--tum", help="write the trajectory as TUM lines (stamp x y z qx qy qz qw)")
    r.add_argument("--diagnostics", help="write one JSON diagnostics record per update (JSON lines)")
    r.add_argument("--plot", help="write a PNG of the trajectory and NIS per sensor")
    r.add_argument("--report", metavar="DIR", help="write an HTML report (plots, doctor's verdicts) into DIR")
    r.add_argument("--quiet", action="store_true",
                   help="no progress bar, no summary (and no doctor, unless --plot or --report reads it)")
    r.add_argument("--reference", metavar="TOPIC",
                   help="score the published trajectory against this bag topic (PoseStamped, "
                        "PoseWithCovarianceStamped, Odometry or NavSatFix; never fused), beside plain baselines")
    r.add_argument("--fuse-every", type=int, default=1, metavar="N",
                   help="fuse only every Nth message of the gps / absolute pose sensor and score on the others "
                        "(default 1: all; without --reference the held-back messages are the reference)")
    r.add_argument("--segment-gap", type=float, default=1.0, metavar="S",
                   help="a reference silent longer than S seconds splits the scoring into segments (default 1)")
    r.add_argument("--rpe-s", type=float, default=1.0, metavar="S",
                   help="relative pose error over S seconds (default 1)")
    r.add_argument("--evaluation", metavar="OUT.json", help="write the evaluation (every score) as JSON")
    r.add_argument("--smooth", action="store_true",
                   help="after the forward pass, smooth it (Rauch-Tung-Striebel, docs/SMOOTHER.md): --tum holds the "
                        "smoothed poses, --reference scores them beside the filtered ones")
    r.add_argument("--advice-budget-s", **ADVICE_BUDGET)
    r.add_argument("--allow-missing", **ALLOW_MISSING)
    r.set_defaults(func=cmd_replay)

    dr = sub.add_parser("doctor", help="replay bags and print the doctor's verdicts with the summary; writes no file "
                                       "(replay without outputs)")
    dr.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    dr.add_argument("--config", required=True, help="TOML config (see config.toml)")
    dr.add_argument("--advice-budget-s", **ADVICE_BUDGET)
    dr.add_argument("--allow-missing", **ALLOW_MISSING)
    dr.set_defaults(func=cmd_doctor)

    it = sub.add_parser("init", help="write a starting config from a bag (topics, types, mounts), each choice "
                                     "commented, then replay it with the doctor")
    it.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    it.add_argument("--out", required=True, metavar="FILE", help="the config to write")
    it.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    it.set_defaults(func=cmd_init)

    inf = sub.add_parser("info", help="a bag's topics, types, counts, rates, stated covariances and what fusiond "
                                      "would use each for")
    inf.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    inf.set_defaults(func=cmd_info)

    rp = sub.add_parser("report", help="replay bags and write the HTML report (plots, the doctor's verdicts) into "
                                       "DIR (replay --report DIR)")
    rp.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    rp.add_argument("--config", required=True, help="TOML config (see config.toml)")
    rp.add_argument("--out", required=True, metavar="DIR", help="directory to write index.html and its images into")
    rp.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    rp.add_argument("--advice-budget-s", **ADVICE_BUDGET)
    rp.add_argument("--allow-missing", **ALLOW_MISSING)
    rp.set_defaults(func=cmd_report)

    tu = sub.add_parser("tune", help="fit the configured sensors' and the process's noise to bags by the innovations' "
                                     "likelihood, check it on the held-back last 30 %%, write the tuned config")
    tu.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    tu.add_argument("--config", required=True, help="TOML config (see config.toml): the sensors and the start")
    tu.add_argument("--out", required=True, metavar="TUNED.toml", help="write the complete tuned config here")
    tu.add_argument("--keys", action="append", metavar="KEY[,KEY]",
                    help="fit only these (e.g. imu.gyro_noise, wheel.twist_noise, filter); default: every tunable key")
    tu.add_argument("--budget-s", type=float, default=120.0, metavar="S",
                    help="stop the fit after S seconds of replays (default 120; the held-back check runs after)")
    tu.add_argument("--quiet", action="store_true", help="no progress bar")
    tu.add_argument("--allow-missing", **ALLOW_MISSING)
    tu.set_defaults(func=cmd_tune)

    m = sub.add_parser("monitor", help="live per-sensor innovation/NIS view of running daemons")
    m.add_argument("--connect", action="append", metavar="ENDPOINT", help="Zenoh endpoint to reach the daemons")
    m.add_argument("--config", help="TOML config: [zenoh] table and output keys (optional)")
    m.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    m.add_argument("--timeout", type=_positive, default=5.0,
                   help="seconds to find a daemon before giving up (default 5)")
    m.add_argument("--duration", type=_positive, help="stop after S seconds (default: until Ctrl-C)")
    m.add_argument("--interval", type=_positive, default=1.0, help="refresh period in seconds (default 1)")
    m.add_argument("--json", action="store_true", help="stream JSON lines instead of the terminal view")
    m.add_argument("--fleet", action="store_true", help="one line per daemon (status, link, worst NIS, drops, age), "
                                                        "worst first")
    m.add_argument("--namespace", metavar="NS", help="watch the daemon of this Zenoh namespace only")
    m.add_argument("--stale", type=_positive, metavar="S", help="a daemon whose newest health answer is older "
                   "than S seconds reads lost (default: 3 x --interval, at least 2)")
    m.set_defaults(func=cmd_monitor)
    _add_router_parser(sub)

    c = sub.add_parser("calibrate-imu", help="measure a static IMU's noise and print it as config")
    c.add_argument("--duration", type=_positive, default=60.0, help="seconds to record (default 60)")
    c.add_argument("--bag", help="read the IMU from this bag instead of Zenoh")
    c.add_argument("--start", type=_non_negative, default=0.0, help="with --bag: skip the first S seconds")
    c.add_argument("--config", help="TOML config naming the IMU sensor (key, encoding, extrinsic_rpy)")
    c.add_argument("--sensor", help="which imu sensor of the config (default: the first)")
    c.add_argument("--key", help="the IMU without a config: its Zenoh key (default imu/data, ROS 2 CDR), or with "
                                 "--bag its topic without the leading slash (the wheels then unread: a recording "
                                 "that moved is told by the IMU alone)")
    c.add_argument("--connect", action="append", metavar="ENDPOINT", help="Zenoh endpoint to connect to")
    c.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    c.set_defaults(func=cmd_calibrate_imu)

    bb = sub.add_parser("bench", help="estimator, core and replay benchmarks on a bag")
    bb.add_argument("--bag", help="bag to replay for the core and replay benchmarks (default: the Jackal bag "
                                   "data/jackal_test2.bag of the source tree)")
    bb.add_argument("--config", help="TOML config the bag is replayed with (default: examples/jackal.toml of "
                                     "the source tree)")
    bb.add_argument("--quick", action="store_true", help="fewer repeats")
    bb.add_argument("--latency", action="store_true", help="also the Zenoh end-to-end latency benchmark")
    bb.add_argument("--seconds", type=_positive, default=10.0, help="latency benchmark duration")
    bb.add_argument("--json", action="store_true", help="machine-readable output")
    bb.add_argument("--no-multicast", action="store_true", help=BENCH_NO_MULTICAST)
    bb.set_defaults(func=cmd_bench)

    d = sub.add_parser("run", help="the fusion daemon: subscribe to the sensors on Zenoh, publish the fused pose")
    d.add_argument("--config", required=True, help="TOML config (see config.toml)")
    d.add_argument("--no-multicast", action="store_true",
                   help="do not scout for peers by multicast (overrides zenoh.multicast_scouting)")
    d.set_defaults(func=cmd_run, default_log_level="info")

    pl = sub.add_parser("play", help="publish a bag's sensor topics onto Zenoh as zenoh-bridge-ros2dds would")
    pl.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    pl.add_argument("--config", required=True, help="TOML config: sensors, keys and the [zenoh] section")
    pl.add_argument("--rate", type=_non_negative, default=1.0,
                    help="pace relative to the recording (default 1: the recorded pace); 0 = as fast as possible, "
                         "which a daemon may not keep up with (play reports what its queue dropped)")
    pl.add_argument("--duration", type=_positive, help="play only the first S seconds of the bag")
    pl.add_argument("--connect", action="append", metavar="ENDPOINT",
                    help="Zenoh endpoint to connect to (repeatable); default: the config's connect, else its listen "
                         "endpoints on loopback")
    pl.add_argument("--listen", action="append", metavar="ENDPOINT", help="Zenoh endpoint to listen on (repeatable)")
    pl.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    pl.add_argument("--wait", type=_non_negative, default=5.0,
                    help="wait up to S seconds for the config's daemon to answer on its health key before "
                         "playing, then play anyway (default 5; 0: do not wait)")
    pl.set_defaults(func=cmd_play, default_log_level="info")

    h = sub.add_parser("health", help="query a running daemon's health; exit 0 when it is good enough")
    h.add_argument("--config", help="TOML config of the daemon (health key, namespace, endpoints)")
    h.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="Zenoh endpoint of the daemon (repeatable); default: from the config")
    h.add_argument("--key", help="health key (default: output.health_key of the config)")
    h.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    h.add_argument("--timeout", type=_positive, default=2.0, help="seconds to wait for an answer (default 2)")
    h.add_argument("--min-status", choices=["ok", "degraded", "failed"], default="degraded",
                   help="worst status that still exits 0 (default degraded; failed = any answer)")
    h.set_defaults(func=cmd_health)

    sp = sub.add_parser("set-pose", help="re-initialise a running daemon's filter at a pose (robot_localization's "
                                         "set_pose); prints the new health, whose pose is the one set")
    sp.add_argument("x", type=float, help="position x in the output frame, m")
    sp.add_argument("y", type=float, help="position y, m")
    sp.add_argument("yaw", type=float, nargs="?", default=0.0, help="heading, rad (default 0)")
    sp.add_argument("--z", type=float, default=0.0, help="position z, m (default 0)")
    sp.add_argument("--roll", type=float, default=0.0, help="rad (default 0)")
    sp.add_argument("--pitch", type=float, default=0.0, help="rad (default 0)")
    sp.add_argument("--stamp", type=float, default=0.0,
                    help="time the pose holds at, s (message time); default 0: the filter's current time")
    sp.add_argument("--sigma", type=float, nargs=2, default=(0.0, 0.0), metavar=("POSITION_M", "ATTITUDE_RAD"),
                    help="standard deviations of the pose (default 0 0: exactly this pose)")
    sp.add_argument("--config", help="TOML config of the daemon (set_pose key, namespace, endpoints)")
    sp.add_argument("--connect", action="append", metavar="ENDPOINT",
                    help="Zenoh endpoint of the daemon (repeatable); default: from the config")
    sp.add_argument("--key", help="set_pose key (default: output.set_pose_key of the config)")
    sp.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    sp.add_argument("--timeout", type=_positive, default=2.0, help="seconds to wait for the answer (default 2)")
    sp.set_defaults(func=cmd_set_pose)

    b = sub.add_parser("bench-latency", help="sensor put -> fused pose latency over Zenoh on loopback")
    b.add_argument("--seconds", type=_positive, default=10.0, help="measurement duration (default 10)")
    b.add_argument("--imu-hz", type=_positive, default=1000.0, help="IMU messages per second sent (default 1000)")
    b.add_argument("--odom-hz", type=_positive, default=100.0,
                   help="odometry messages per second sent; each yields a fused pose (default 100)")
    b.add_argument("--express", action="store_true", help="send the daemon's outputs unbatched (Zenoh express)")
    b.add_argument("--json", action="store_true", help="machine-readable output")
    b.add_argument("--no-multicast", action="store_true", help=BENCH_NO_MULTICAST)
    b.set_defaults(func=cmd_bench_latency)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .logs import configure

    configure(args.log_level or getattr(args, "default_log_level", "warning"))
    # The estimator's linear algebra: compiled when built (the default, "auto"), or the numpy
    # reference path (FUSIOND_KERNELS=numpy; estimator/kernels.py). Read here, not in the estimator
    # (no I/O there), and only when set: the commands that do not fuse need not import numpy.
    if os.environ.get("FUSIOND_KERNELS"):
        from .errors import EstimatorError
        from .estimator import kernels

        try:
            kernels.use_environment(os.environ)
        except EstimatorError as e:
            print(f"fusiond: {e}", file=sys.stderr)
            return 2
    try:
        return args.func(args)
    except BrokenPipeError:  # `fusiond doctor ... | head`: the reader left; no traceback for that
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # and none from the interpreter flushing stdout at exit
        return 1


if __name__ == "__main__":
    sys.exit(main())
