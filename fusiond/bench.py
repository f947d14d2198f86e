"""`fusiond bench`: the numbers the closing notes report, measured the same way each time.

- estimator: predict + roll/pitch update of the gyro-bias model, us per step
  (min over repeats: the machine's quietest moment, not its average);
- core: FusionCore.ingest on pre-decoded bag samples, us per message;
- replay in-process (bag decoding + fusion) in msg/s, beside rosbags' own
  decoding rate on the same bag;
- whole `fusiond replay` process wall time beside a bare numpy EKF script
  (scripts/bare_ekf_replay.py), start-up included.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
import timeit
from pathlib import Path

import numpy as np

from .config import Config


def bench_estimator(repeat: int = 7, number: int = 3000) -> dict[str, float]:
    from .estimator import ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock, StateLayout, predict
    from .estimator import observations as obs

    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    ekf = ErrorStateEKF(layout)
    u = MotionInput()
    u.linear, u.angular = (0.5, 0.0, 0.0), (0.01, -0.02, 0.2)
    u.linear_cov = (1e-3, 0, 0, 0, 1e-3, 0, 0, 0, 1e-3)
    u.angular_cov = (2.5e-5, 0, 0, 0, 2.5e-5, 0, 0, 0, 2.5e-5)
    u.linear_period = u.angular_period = 0.02
    u.from_gyro = True
    noise = layout.noise_density(np.full(6, 4e-6))
    cov = (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)
    mask = np.ones(layout.error_dim, dtype=bool)
    mask[[0, 1, 2, 5, 8]] = False

    def predict_only() -> None:
        x, F, Q = predict(layout, ekf.x, u, 0.01, noise)
        ekf.propagate(x, F, Q)

    def update_only() -> None:
        y, H, R = obs.orientation(layout, ekf.x, (0.001, -0.002, 0.0), cov, (0, 1))
        ekf.update(y, H, R, mask=mask)

    def step() -> None:
        predict_only()
        update_only()

    def best(fn) -> float:
        return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6

    return {"predict_us": best(predict_only), "update_us": best(update_only), "predict_update_us": best(step)}


def bench_replay(bag: Path, cfg: Config, repeat: int = 3) -> dict[str, float]:
    from rosbags.highlevel import AnyReader

    from .core.fusion import FusionCore
    from .replay.bag import open_bag_samples
    from .replay.run import replay

    topics = {"/" + s.key for s in cfg.sensors}

    def rosbags_decode() -> int:
        n = 0
        with AnyReader([bag]) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for conn, _, raw in reader.messages(connections=conns):
                reader.deserialize(raw, conn.msgtype)
                n += 1
        return n

    def timed(fn) -> tuple[float, object]:
        t0 = time.perf_counter()
        out = fn()
        return time.perf_counter() - t0, out

    rosbags_s, n = min(timed(rosbags_decode) for _ in range(repeat))
    with open_bag_samples([bag], cfg.sensors) as b:
        samples = list(b)

    def fuse() -> None:
        core = FusionCore(cfg)
        for s in samples:
            if core.ingest(s).publish:
                core.pose()

    core_s = min(timed(fuse)[0] for _ in range(repeat))
    replay_s = min(timed(lambda: replay([bag], cfg, keep_trace=False, progress=False))[0] for _ in range(repeat))
    return {
        "messages": float(n),
        "rosbags_decode_msg_s": n / rosbags_s,
        "core_us_per_msg": core_s / len(samples) * 1e6,
        "replay_in_process_msg_s": len(samples) / replay_s,
        "replay_vs_rosbags": (len(samples) / replay_s) / (n / rosbags_s),
    }


def bench_process(bag: Path, config: Path, topics: tuple[str, str], repeat: int = 3) -> dict[str, float]:
    root = Path(__file__).resolve().parents[1]
    bare = root / "scripts" / "bare_ekf_replay.py"

    def wall(cmd: list[str]) -> float:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
        return statistics.median(times)

    out = {"fusiond_replay_s": wall([sys.executable, "-m", "fusiond", "replay", str(bag), "--config", str(config),
                                     "--quiet"])}
    if bare.is_file():
        out["bare_numpy_script_s"] = wall([sys.executable, str(bare), str(bag), *topics])
    return out


def run(bag: Path, config: Path, cfg: Config, quick: bool = False) -> dict[str, dict[str, float]]:
    result = {"estimator": bench_estimator(repeat=3 if quick else 7, number=1000 if quick else 3000)}
    if bag.is_file():
        result["replay"] = bench_replay(bag, cfg, repeat=1 if quick else 3)
        odom = next(s for s in cfg.sensors if type(s).__name__ == "OdomSensor")
        imu = next((s for s in cfg.sensors if type(s).__name__ == "ImuSensor"), odom)
        result["process"] = bench_process(bag, config, ("/" + odom.key, "/" + imu.key), repeat=1 if quick else 3)
    return result


def format_table(result: dict[str, dict[str, float]]) -> str:
    lines = []
    for section, values in result.items():
        for k, v in values.items():
            lines.append(f"{section:<10} {k:<26} {v:>12,.2f}")
    return "\n".join(lines)
