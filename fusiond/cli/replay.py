"""`fusiond replay BAG [BAG ...] --config FILE [--tum OUT] ...`: bags through the fusion core, as the daemon
would have fused them; optionally scored against a reference topic, with the doctor's verdicts and advice.

`doctor`, `report` and `init` are this command with other options (``as_replay``), not copies of it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import (ADVICE_BUDGET, ALLOW_MISSING, EXIT_USAGE, chosen_backend,
                     holds_recording, load_config, output_error)

__all__ = ["add_arguments", "as_replay", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    holds_recording(p)
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    p.add_argument("--config", required=True, help="TOML config (see config.toml)")
    p.add_argument("--tum", help="write the trajectory as TUM lines (stamp x y z qx qy qz qw)")
    p.add_argument("--diagnostics", help="write one JSON diagnostics record per update (JSON lines)")
    p.add_argument("--plot", help="write a PNG of the trajectory and NIS per sensor")
    p.add_argument("--report", metavar="DIR", help="write an HTML report (plots, doctor's verdicts) into DIR")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar, no summary, no log lines below error unless --log-level says "
                        "(and no doctor, unless --plot or --report reads it)")
    p.add_argument("--reference", metavar="TOPIC",
                   help="score the published trajectory against this bag topic (PoseStamped, "
                        "PoseWithCovarianceStamped, Odometry or NavSatFix; never fused), beside plain baselines")
    p.add_argument("--fuse-every", type=int, default=1, metavar="N",
                   help="fuse only every Nth message of the gps / absolute pose sensor and score on the others "
                        "(default 1: all; without --reference the held-back messages are the reference)")
    p.add_argument("--segment-gap", type=float, default=1.0, metavar="S",
                   help="a reference silent longer than S seconds splits the scoring into segments (default 1)")
    p.add_argument("--rpe-s", type=float, default=1.0, metavar="S",
                   help="relative pose error over S seconds (default 1)")
    p.add_argument("--evaluation", metavar="OUT.json", help="write the evaluation (every score) as JSON")
    p.add_argument("--smooth", action="store_true",
                   help="after the forward pass, smooth it (Rauch-Tung-Striebel, docs/SMOOTHER.md): --tum holds the "
                        "smoothed poses, --reference scores them beside the filtered ones")
    p.add_argument("--advice-budget-s", **ADVICE_BUDGET)
    p.add_argument("--allow-missing", **ALLOW_MISSING)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, needs="replay")
    for option, value, directory in (("--tum", args.tum, False), ("--diagnostics", args.diagnostics, False),
                                     ("--plot", args.plot, False), ("--report", args.report, True),
                                     ("--evaluation", args.evaluation, False)):
        problem = output_error(value, option, directory) if value else None
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
    from ..errors import ReplayError

    reference = args.reference
    fuse_every = args.fuse_every
    recorder = None
    if reference or fuse_every > 1:
        from ..replay.evaluate import Recorder

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
        else:  # a mistyped topic is refused before the recording is fused, not after
            from ..replay.evaluate import check_reference

            try:
                check_reference([Path(p) for p in args.bags], reference)
            except ReplayError as err:
                print(f"fusiond: {err}", file=sys.stderr)
                return EXIT_USAGE
    if not args.advice_budget_s >= 0.0:
        print(f"fusiond: --advice-budget-s {args.advice_budget_s:g}: must be 0 or a positive number of seconds",
              file=sys.stderr)
        return EXIT_USAGE
    doctor = not args.quiet or bool(args.plot or args.report)  # --quiet: no summary to judge for
    # the samples as fused are kept to replay the doctor's advice on (what --fuse-every left, in bag order:
    # ``ReplayResult.samples``), and what the replay made of them
    proves = doctor and args.advice_budget_s > 0.0
    records: list | None = [] if proves else None
    through = recorder.filter if recorder is not None else None
    # the bags opened and read in a child from here on, while the filter and the doctor are imported and built
    from ..replay.read_ahead import reading_ahead

    bags = [Path(p) for p in args.bags]
    # ... and, where every sample it reads reaches the doctor (no evaluation holding fixes back), the doctor's
    # sample part made there too, beside the filter (read_ahead's module doc)
    reading = reading_ahead(bags, cfg.sensors, cfg if proves and recorder is None else None)
    try:
        from ..replay.run import replay, summary

        if proves and reading is not None:  # the proof's modules too, while the child opens the bags (it takes longer)
            from ..tune import advice, likelihood  # noqa: F401
    except BaseException:
        if reading is not None:
            reading.close()
        raise
    backend = chosen_backend()
    try:
        result = replay(
            bags,
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
            backend=backend,
            lookahead=proves,  # the recording is kept in memory for the advice's proof anyway
            reading=reading,
        )
        evaluation = None
        fused = result.samples if proves else None

        def prove():
            from ..tune.advice import prove_advice
            from ..tune.likelihood import Plans

            plans = Plans(fused)
            if result.plan is not None:  # the recording's own replay planned it: its lines' replays need not
                plans.add(cfg, result.plan)
            return prove_advice(cfg, fused, result.verdicts(), args.advice_budget_s, records, backend,
                                base_final=result.final, base_applied=result.applied, plans=plans)

        def score():
            from ..replay.evaluate import evaluate

            return evaluate([Path(p) for p in args.bags], cfg, reference, result.trajectory, recorder,
                            segment_gap_s=args.segment_gap, rpe_s=args.rpe_s,
                            heading_known=result.heading_known, smoothed=result.smoothed)

        if fused and recorder is not None:  # neither reads the other: the advice's replays beside the scoring
            from ..tune.forked import beside

            evaluation, result.proven = beside(score, prove)
        elif fused:
            result.proven = prove()
        elif recorder is not None:
            evaluation = score()
    except ReplayError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    if evaluation is not None and args.evaluation:
        import msgspec

        Path(args.evaluation).parent.mkdir(parents=True, exist_ok=True)
        Path(args.evaluation).write_bytes(msgspec.json.format(msgspec.json.encode(evaluation)))
    evaluation_text = None
    if evaluation is not None:
        from ..replay.evaluate import format_evaluation

        evaluation_text = format_evaluation(evaluation)
    title = ", ".join(Path(b).name for b in args.bags)
    if args.plot:
        from ..replay.plot import plot_replay

        plot_replay(result, Path(args.plot), title=title)
    if args.report:
        from ..replay.report import write_report

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


def as_replay(bags: list[str], config: str, *options: str) -> argparse.Namespace:
    """The replay command's own arguments for these bags and options, parsed by its own parser (every
    default as `fusiond replay` has it), so that `doctor` and `report` are that command, not a copy."""
    from . import build_parser

    return build_parser(("replay",)).parse_args(["replay", "--config", config, *options, "--", *bags])
