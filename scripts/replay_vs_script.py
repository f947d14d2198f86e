"""Whole-process `fusiond replay` against a user's own replay script, per shared recording (a benchmark).

The yardstick is `../shared/perf/replay_script.py --impl tight7`: a tight numpy EKF over the bag read
with rosbags' AnyReader, one TUM line per message, as one process (that folder's README says how the
ratio is taken). `fusiond replay BAG --config CFG --tum OUT` runs as a user runs it: the doctor, its
advice's proof and the summary on. Each recording is timed in pairs, fusiond then the script,
alternated, and the ratio is the median of the per-pair wall-time ratios (pairing keeps it meaningful
while other work on the machine moves the absolute times); min and max show the spread.

    python scripts/replay_vs_script.py [--pairs 7] [--yard PYTHON] [--all-configs] [--json OUT]

PYTHON is an interpreter with numpy, scipy and rosbags (``python -m venv .yard && .yard/bin/pip
install numpy scipy rosbags``; default: $YARD_PYTHON, else /tmp/.yard/bin/python). Before timing, each
recording is read once by the script (it must find its odometry and IMU topics) and once by fusiond.
A benchmark, not a test: nothing is asserted, the table is printed (and written as JSON with --json).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
# (recording under shared/data, config under examples/): the first config of each recording is the one
# its README and docs/RESULTS.md score; --all-configs adds the others
RECORDINGS = [
    ("jackal_test2.bag", "jackal_rl.toml"),
    ("comma2k19_ex1", "comma2k19.toml"),
    ("f110_ds2", "f110.toml"),
]
MORE = [
    ("jackal_test2.bag", "jackal.toml"),
    ("comma2k19_ex1", "comma2k19_odom_imu.toml"),
    ("f110_ds2", "f110_imu_yaw.toml"),
    ("f110_ds2", "f110_new_user.toml"),
]


def _wall(cmd: list[str]) -> float:
    """Seconds of one whole run of ``cmd`` (its output discarded); an error when it fails."""
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def _commands(bag: Path, config: str, yard: str, out: Path) -> tuple[list[str], list[str]]:
    fusiond = [str(ROOT / ".venv" / "bin" / "fusiond"), "replay", str(bag), "--config", str(ROOT / "examples" / config),
               "--tum", str(out / "fusiond.tum")]
    script = [yard, str(SHARED / "perf" / "replay_script.py"), str(bag), "--tum", str(out / "script.tum"),
              "--impl", "tight7"]
    return fusiond, script


def _readable(script: list[str]) -> str | None:
    """None when the script reads the recording (it prints its message count), else why not."""
    r = subprocess.run(script, capture_output=True, text=True)
    if r.returncode != 0 or "messages=" not in r.stdout:
        return (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
    return None


def measure(bag: Path, config: str, yard: str, pairs: int) -> dict:
    """One recording's row: per-pair ratios and the median times of each side."""
    with tempfile.TemporaryDirectory() as tmp:
        fusiond, script = _commands(bag, config, yard, Path(tmp))
        problem = _readable(script)
        if problem is not None:
            return {"recording": bag.name, "config": config, "script_cannot_read": problem}
        _wall(fusiond)  # warm-up of both (the page cache, the byte-compiled modules)
        walls_f, walls_s, ratios = [], [], []
        for _ in range(pairs):
            a = _wall(fusiond)
            b = _wall(script)
            walls_f.append(a)
            walls_s.append(b)
            ratios.append(a / b)
    return {"recording": bag.name, "config": config, "pairs": pairs, "ratio_median": statistics.median(ratios),
            "ratio_min": min(ratios), "ratio_max": max(ratios), "fusiond_s": statistics.median(walls_f),
            "script_s": statistics.median(walls_s), "ratios": ratios}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=7)
    ap.add_argument("--yard", default=os.environ.get("YARD_PYTHON", "/tmp/.yard/bin/python"),
                    help="a Python with numpy, scipy and rosbags")
    ap.add_argument("--all-configs", action="store_true", help="also the recordings' other example configs")
    ap.add_argument("--json", type=Path, help="write the rows here")
    a = ap.parse_args(argv)
    rows = []
    print("| recording | config | fusiond replay s | script s | ratio, median of pairs | min-max |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, config in RECORDINGS + (MORE if a.all_configs else []):
        bag = SHARED / "data" / name
        if not bag.exists():
            print(f"| {name} | {config} | not in {SHARED / 'data'} | | | |")
            continue
        row = measure(bag, config, a.yard, a.pairs)
        rows.append(row)
        if "script_cannot_read" in row:
            print(f"| {name} | {config} | - | the script cannot read it: {row['script_cannot_read']} | | |")
        else:
            print(f"| {name} | {config} | {row['fusiond_s']:.3f} | {row['script_s']:.3f} | "
                  f"{row['ratio_median']:.3f} ({row['pairs']} pairs) | {row['ratio_min']:.3f}-{row['ratio_max']:.3f} |",
                  flush=True)
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
