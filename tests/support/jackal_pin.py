"""The Jackal trajectory pin: what the fusion core estimates on the shared Jackal bag.

The pin file (tests/data/jackal_pin.json) holds, per example config, every 50th
published pose (the one `fusiond replay` writes to TUM at that odometry message)
and the final one, with the 1-sigma of position and attitude, plus the per-sensor
counters. tests/e2e/test_trajectory_pin.py compares a fresh replay with it to 1e-9 m /
1e-9 rad: a refactor or a speed-up must not move any estimate. A deliberate
behaviour change regenerates it (`python tests/data/regen_jackal_pin.py`) in its own
commit, whose message says why the estimates moved.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PIN_PATH = ROOT / "tests" / "data" / "jackal_pin.json"
# The robot_localization-like config (absolute IMU yaw, no gyro) and the recommended one
# (gyro + bias drive heading, masked roll/pitch update): together they run every estimator
# path the Jackal bag can reach (plain and Schmidt updates, bias state, late re-application).
CONFIGS = ("examples/jackal_rl.toml", "examples/jackal.toml")
EVERY = 50
DECIMALS = 12


def trajectory(bag: Path, config: str, backend=None) -> dict:
    """Replay ``bag`` through FusionCore with ``config`` (and ``backend``, the estimator's; None: the
    default): sampled poses, their sigmas, the counters."""
    from fusiond.config import load
    from fusiond.core.fusion import FusionCore
    from fusiond.replay.bag import open_bag_samples

    cfg = load(ROOT / config)
    core = FusionCore(cfg, backend)
    poses: list[list[float]] = []
    last: list[float] | None = None
    n = 0
    with open_bag_samples([bag], cfg.sensors) as samples:
        for sample in samples:
            if not core.ingest(sample).publish:
                continue
            t, x = core.pose()
            d = core.state.ekf.P.diagonal()
            row = [t, *x.tolist(), *(math.sqrt(v) for v in d[0:6].tolist())]
            last = [round(v, DECIMALS) for v in row]
            if n % EVERY == 0:
                poses.append(last)
            n += 1
    if last is not None and (not poses or poses[-1] is not last):
        poses.append(last)
    counters = {s.name: {"received": st.received, "applied": st.applied, "late": st.late,
                         "rejected": st.rejected, "dropped": dict(sorted(st.dropped.items()))}
                for s, st in zip(core.sensors, core.stats)}
    return {"published": n, "every": EVERY, "columns": "t x y z qx qy qz qw sx sy sz sroll spitch syaw",
            "poses": poses, "counters": counters, "covariance_resets": core.covariance_resets}


def compute(bag: Path) -> dict:
    return {config: trajectory(bag, config) for config in CONFIGS}


def write(bag: Path, path: Path = PIN_PATH) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    """One pose per line, so that a regenerated pin reads as a diff of poses."""
    parts = []
    for config, run in compute(bag).items():
        head = {k: v for k, v in run.items() if k != "poses"}
        rows = ",\n".join("   " + json.dumps(r) for r in run["poses"])
        parts.append(f" {json.dumps(config)}: {{\n  \"meta\": {json.dumps(head)},\n  \"poses\": [\n{rows}\n  ]\n }}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("{\n" + ",\n".join(parts) + "\n}\n")
    return path
