"""The smoother's table over the real recordings in ../shared/data: filtered / smoothed / plain baseline.

Every case is `fusiond replay BAG --config CFG --reference /ground_truth [--fuse-every N] --smooth` run
in-process (the same replay and evaluation), the rows it prints for fusiond, fusiond smoothed and the
baseline the case is judged against (the fused fixes interpolated with thinned fixes, the raw fixes with
every fix). With a GPS the table adds the same scores over the stamps after the filter first knew its
heading (``ReplayResult.heading_known``): before that the published position is the GPS search's, not an
estimate of the state, and the smoother keeps it as published (docs/SMOOTHER.md). A benchmark, not a test.

    .venv/bin/python scripts/smoother_table.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CASES = (  # recording, config, --fuse-every, metric, baseline
    ("comma2k19_ex1", "comma2k19.toml", 10, "world_h", "fused fixes interpolated"),
    ("comma2k19_ex1", "comma2k19.toml", 1, "world_h", "raw fixes"),
    ("comma2k19_ex1", "comma2k19_odom_imu.toml", 1, "aligned_h", None),
    ("f110_ds2", "f110.toml", 1, "aligned_h", None),
    ("f110_ds2", "f110_imu_yaw.toml", 1, "aligned_h", None),
)


def run(data: Path, recording: str, config: str, fuse_every: int):
    from fusiond.config import load
    from fusiond.replay.evaluate import Recorder, evaluate
    from fusiond.replay.run import replay

    bag = [data / recording]
    cfg = load(ROOT / "examples" / config)
    rec = Recorder(cfg, fuse_every)
    r = replay(bag, cfg, progress=False, doctor=False, through=rec.filter, smooth=True)
    ev = evaluate(bag, cfg, "/ground_truth", r.trajectory, rec, heading_known=r.heading_known, smoothed=r.smoothed)
    return r, rec, ev


def after_heading(data: Path, recording: str, r, rec, ev) -> dict[str, float]:
    """World RMS horizontal error of fusiond, smoothed and the fixes' baselines over the scoring stamps
    after the first published pose whose heading was known."""
    from fusiond.replay.evaluate import Track, baseline_tracks, read_reference
    from fusiond.estimator.geodesy import EnuFrame

    tr = np.asarray(r.trajectory).reshape(-1, 8)
    known = np.asarray(r.heading_known, dtype=bool)
    if not known.any():
        return {}
    t_known = tr[np.argmax(known), 0]
    _, rt, rpos, rhead, _ = read_reference([data / recording], "/ground_truth")
    ref = Track.build("ref", rt, rpos, rhead)
    if rec.fuse_every > 1:
        ts = np.array(sorted(h[0] for h in rec.held_fixes if h[4] >= 0))
    else:
        ts = ref.t
    ts = ts[ts > t_known]
    first = min(f for f in rec.fused_fixes if f[4] >= 0)
    frame = EnuFrame(*first[1:4])
    sm = np.asarray(r.smoothed).reshape(-1, 8)
    tracks = [Track.build("fusiond", tr[:, 0], tr[:, 1:4]), Track.build("fusiond smoothed", sm[:, 0], sm[:, 1:4])]
    tracks += [t for t in baseline_tracks(rec, frame, 1.0, after_the_fact=True)
               if t.name in ("raw fixes", "fused fixes interpolated")]
    rx, _, rv = ref.at(ts, 1.0)
    out = {}
    for t in tracks:
        xyz, _, v = t.at(ts, 1.0)
        v = v & rv
        d = xyz[v, :2] - rx[v, :2]
        out[t.name] = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    args = ap.parse_args()
    if not (args.data / "comma2k19_ex1").exists():
        print(f"no recordings in {args.data}", file=sys.stderr)
        return 2
    print(f"{'recording':<14} {'config':<24} {'fuse':>4} {'metric':<10} {'segment':<8} {'filtered':>8} "
          f"{'smoothed':>8} {'baseline':>8}  baseline")
    for recording, config, every, metric, base in CASES:
        r, rec, ev = run(args.data, recording, config, every)
        by = {(s.segment, s.method): s for s in ev.scores}
        for seg in dict.fromkeys(s.segment for s in ev.scores):
            f, s = by[(seg, "fusiond")], by[(seg, "fusiond smoothed")]
            b = by.get((seg, base)) if base else None
            cell = f"{getattr(b, metric):8.3f}" if b is not None else f"{'-':>8}"
            print(f"{recording:<14} {config:<24} {every:>4} {metric:<10} {seg:<8} {getattr(f, metric):8.3f} "
                  f"{getattr(s, metric):8.3f} {cell}  {base or '-'}")
        if base:
            ah = after_heading(args.data, recording, r, rec, ev)
            if ah:
                print(f"{recording:<14} {config:<24} {every:>4} {metric:<10} {'heading':<8} {ah['fusiond']:8.3f} "
                      f"{ah['fusiond smoothed']:8.3f} {ah.get(base, float('nan')):8.3f}  {base} (after the "
                      "heading is known)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
