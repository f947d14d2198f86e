"""The real recordings as another recording of the same kind would differ: fusiond beside the plain
baselines on each variant.

A recording fusiond is judged on starts elsewhere (a car already at speed when the heading is
searched for), loses its GPS for a while, gets its fixes less often, or sees a multipath burst.
Each variant here is written from a recording in ../shared/data (a ROS 2 bag: its messages are
copied, the fixes edited through rosbags' own CDR codec), then replayed and scored exactly as
`fusiond replay BAG --config CFG --reference /ground_truth` does. A benchmark, not a test: it
asserts nothing and prints the table (docs/RESULTS.md, "Variants of the real recordings").

    .venv/bin/python scripts/recording_variants.py [--data ../shared/data] [--only NAME]

A variant that starts later keeps the original's world frame (the reference is ENU at the
original first fix): its config names that fix as the GPS datum.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EARTH_RADIUS = 6378137.0  # m, WGS84 equatorial: a burst's metres turned into degrees


@dataclass(frozen=True)
class Variant:
    name: str
    recording: str  # under the data folder
    config: str  # under examples/
    what: str
    # (topic, seconds after the first message, message) -> the message to write, or None to drop it;
    # the message is deserialised only for the topics in ``edits``
    edit: Callable[[str, float, object], object | None]
    edits: tuple[str, ...] = ()
    metrics: tuple[str, ...] = ("world_h", "aligned_h")
    # the raw fixes know the next fix (read between two) and are scored only where there are fixes; holding
    # or extrapolating the last one is what a GPS-only user has at each moment, through an outage too
    baselines: tuple[str, ...] = ("raw fixes", "hold last fused fix", "fixes at constant velocity")
    segment: str = "all"
    keep_datum: bool = False  # name the original's first fix as the datum (a variant that starts later)


def _keep(topic: str, rel: float, msg: object) -> object:
    return msg


def _start_at(t0: float) -> Callable:
    return lambda topic, rel, msg: msg if rel >= t0 else None


def _outage(t0: float, seconds: float) -> Callable:
    return lambda topic, rel, msg: None if topic == "/fix" and t0 <= rel < t0 + seconds else msg


def _every_nth_fix(n: int) -> Callable:
    count = {"fixes": 0}

    def edit(topic: str, rel: float, msg: object) -> object | None:
        if topic != "/fix":
            return msg
        count["fixes"] += 1
        return msg if (count["fixes"] - 1) % n == 0 else None
    return edit


def _burst(t0: float, fixes: int, east: float, north: float) -> Callable:
    """``fixes`` fixes from t0 on moved by (east, north) m: a multipath burst."""
    left = {"n": None}

    def edit(topic: str, rel: float, msg) -> object | None:
        if topic != "/fix" or rel < t0:
            return msg
        if left["n"] is None:
            left["n"] = fixes
        if left["n"] > 0:
            left["n"] -= 1
            msg.latitude += math.degrees(north / EARTH_RADIUS)
            msg.longitude += math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(msg.latitude))))
        return msg
    return edit


COMMA, F110 = "comma2k19_ex1", "f110_ds2"
F110_BASELINES = ("gyro + wheel speed", "wheel odometry")
VARIANTS = (
    Variant("comma_copy", COMMA, "comma2k19.toml", "highway car, as recorded (the control)", _keep),
    Variant("comma_start10", COMMA, "comma2k19.toml", "highway car, starting 10 s in (at 15 m/s)", _start_at(10.0),
            keep_datum=True),
    Variant("comma_start20", COMMA, "comma2k19.toml", "highway car, starting 20 s in (at 19 m/s)", _start_at(20.0),
            keep_datum=True),
    Variant("comma_start30", COMMA, "comma2k19.toml", "highway car, starting 30 s in", _start_at(30.0),
            keep_datum=True),
    Variant("comma_outage20", COMMA, "comma2k19.toml", "highway car, no fix for 20 s from 25 s", _outage(25.0, 20.0)),
    Variant("comma_1hz", COMMA, "comma2k19.toml", "highway car, fixes at 1 Hz", _every_nth_fix(10)),
    Variant("comma_burst", COMMA, "comma2k19.toml", "highway car, 20 fixes 15 m east from 30 s", _burst(30.0, 20, 15.0, 0.0),
            edits=("/fix",)),
    Variant("comma_burst_early", COMMA, "comma2k19.toml", "highway car, 5 fixes 15 m east from 0.5 s (heading unknown)",
            _burst(0.5, 5, 15.0, 0.0), edits=("/fix",)),
    Variant("f110_start20", F110, "f110_imu_yaw.toml", "F1/10 car, IMU yaw relative, starting 20 s in",
            _start_at(20.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
    Variant("f110_start60", F110, "f110_imu_yaw.toml", "F1/10 car, IMU yaw relative, starting 60 s in",
            _start_at(60.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
    Variant("f110_off_start60", F110, "f110.toml", "F1/10 car, orientation off, starting 60 s in",
            _start_at(60.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
)
UNITS = {"world_h": "m world", "aligned_h": "m aligned", "heading_deg": "deg heading"}


def write_variant(src: Path, out: Path, v: Variant) -> tuple[float, float, float] | None:
    """Write ``v`` of the ROS 2 bag ``src`` to ``out``; the original's first fix (lat, lon, alt), if any."""
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    first_fix = None
    with Reader(src) as reader, Writer(out, version=8) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        t0 = reader.start_time
        for c, t, raw in reader.messages():
            rel = (t - t0) / 1e9
            decoded = c.topic in v.edits or (c.topic == "/fix" and first_fix is None)
            msg = store.deserialize_cdr(raw, c.msgtype) if decoded else raw
            if c.topic == "/fix" and first_fix is None and msg.status.status >= 0:
                first_fix = (msg.latitude, msg.longitude, msg.altitude)
            kept = v.edit(c.topic, rel, msg)
            if kept is None:
                continue
            writer.write(conns[c.id], t, store.serialize_cdr(kept, c.msgtype) if c.topic in v.edits else raw)
    return first_fix


def score(data: Path, v: Variant, work: Path) -> dict[str, tuple[tuple[float, int] | None, list]]:
    """Per metric: fusiond's (value, points scored), and each baseline's (name, value, points scored),
    on the variant's segment."""
    import msgspec

    from fusiond.config import GpsSensor, load
    from fusiond.replay.evaluate import Recorder, evaluate
    from fusiond.replay.run import replay

    bag = work / v.name
    first_fix = write_variant(data / v.recording, bag, v)
    cfg = load(ROOT / "examples" / v.config)
    if v.keep_datum and first_fix is not None:
        cfg = msgspec.structs.replace(cfg, sensors=[msgspec.structs.replace(s, datum=first_fix)
                                                    if isinstance(s, GpsSensor) else s for s in cfg.sensors])
    rec = Recorder(cfg)
    result = replay([bag], cfg, keep_trace=False, progress=False, doctor=False, through=rec.filter)
    ev = evaluate([bag], cfg, "/ground_truth", result.trajectory, rec, heading_known=result.heading_known)
    by = {sc.method: sc for sc in ev.scores if sc.segment == v.segment}
    out = {}
    for metric in v.metrics:
        ours = (getattr(by["fusiond"], metric), by["fusiond"].n) if "fusiond" in by else None
        base = [(m, getattr(by[m], metric), by[m].n) for m in v.baselines
                if m in by and getattr(by[m], metric) is not None]
        out[metric] = (ours, base)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"), help="the recordings' folder")
    ap.add_argument("--only", help="one variant by name")
    args = ap.parse_args()
    data = Path(args.data)
    from fusiond.logs import configure

    configure("warning")
    if not (data / COMMA).exists():
        print(f"recording_variants: no recordings in {data}", file=sys.stderr)
        return 2
    chosen = [v for v in VARIANTS if args.only in (None, v.name)]
    if not chosen:
        print(f"recording_variants: no variant {args.only!r}; one of {', '.join(v.name for v in VARIANTS)}",
              file=sys.stderr)
        return 2
    started = time.perf_counter()
    print("| variant | case | segment | metric | fusiond (points scored) | plain baselines (points scored) |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="fusiond-variants-") as tmp:
        for v in chosen:
            for metric, (ours, base) in score(data, v, Path(tmp)).items():
                ours_s = "-" if ours is None else f"{ours[0]:.3f} {UNITS[metric]} ({ours[1]})"
                base_s = "; ".join(f"{name} {value:.3f} ({n})" for name, value, n in base) or "-"
                print(f"| {v.name} | {v.what} | {v.segment} | {metric} | {ours_s} | {base_s} |", flush=True)
    print(f"({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
