"""`fusiond bench`: the numbers the closing notes report, measured the same way each time.

- estimator: predict + roll/pitch update of the gyro-bias model, us per step
  (min over repeats: the machine's quietest moment, not its average);
- sensors: us per update of each issue-7 sensor (GPS position, absolute pose,
  pose delta), as estimator calls and as FusionCore.ingest on a synthetic
  odom/IMU/GPS/pose stream, and the core's us per message with and without them;
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


def bench_sensors(repeat: int = 5, number: int = 2000, seconds: float = 20.0) -> dict[str, float]:
    """us per update of the GPS and pose sensors (estimator level, then through the core)."""
    import math

    from .config import loads
    from .core.fusion import FusionCore
    from .estimator import ErrorStateEKF, GyroBiasBlock, GyroScaleBlock, PoseBlock, StateLayout, WheelScaleBlock
    from .estimator import observations as obs
    from .estimator import rotation as rot
    from .estimator.geodesy import EnuFrame, enu_to_geodetic
    from .samples import GpsSample, ImuSample, OdomSample, PoseSample

    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5), GyroScaleBlock(0.05, 1e-5),
                          WheelScaleBlock(0.1, 1e-4)])
    ekf = ErrorStateEKF(layout)
    cov3 = (0.09, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 0.09)
    cov6 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    lever = (0.3, 0.1, 0.5)
    x_prev = ekf.x.copy()
    rows = (0, 1, 2, 3, 4, 5)
    q = (0.0, 0.0, 0.0, 1.0)

    def gps_update() -> None:
        y, H, R = obs.position(layout, ekf.x, (0.01, -0.02, 0.0), cov3, lever)
        ekf.update(y, H, R)

    def pose_update() -> None:
        y, H, R = obs.pose(layout, ekf.x, (0.01, -0.02, 0.0), (0.0, 0.0, 0.001), cov6, rows, lever)
        ekf.update(y, H, R)

    def delta_update() -> None:
        y, H, R = obs.delta_pose(layout, ekf.x, x_prev, (0.01, 0.0, 0.0), q, cov6, rows, lever)
        ekf.update(y, H, R)

    def best(fn) -> float:
        return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6

    out = {"gps_update_us": best(gps_update), "pose_update_us": best(pose_update),
           "pose_delta_update_us": best(delta_update)}

    # Through the core: a robot driving a circle; odom 50 Hz, IMU 100 Hz, GPS 5 Hz, pose 10 Hz.
    enu = EnuFrame(48.137, 11.575, 520.0)
    stream: list = []
    cov36 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    gcov = (1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6)
    for k in range(int(seconds * 100)):
        t = 1000.0 + 0.01 * k
        yaw = 0.2 * (t - 1000.0)
        px, py = 5.0 * math.sin(yaw), 5.0 - 5.0 * math.cos(yaw)
        stream.append(ImuSample("imu", t, (0.0, 0.0, 0.0, 1.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e6),
                                (0.0, 0.0, 0.2), gcov))
        if k % 2 == 0:
            stream.append(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.2), cov36))
        if k % 20 == 0:
            lat, lon, alt = enu_to_geodetic(enu, px, py, 0.0)
            stream.append(GpsSample("gps", t, lat, lon, alt, 0, cov3, 2))
        if k % 10 == 5:
            stream.append(PoseSample("pose", t, (px, py, 0.0), rot.from_rpy(0.0, 0.0, yaw), cov6))
    base = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
scale_estimation = true
[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
angular_velocity = true
gyro_scale_estimation = true
"""
    configs = {
        "gps": base + '[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "gps"\ndatum = [48.137, 11.575, 520.0]\n',
        "pose": base + '[[sensors]]\nname = "pose"\nkind = "pose"\nkey = "pose"\n',
        "pose_differential": base + '[[sensors]]\nname = "pose"\nkind = "pose"\nkey = "pose"\ndifferential = true\n',
        "odom_imu_only": base,
    }
    clock = time.perf_counter
    for label, text in configs.items():
        cfg = loads(text)
        names = {s.name for s in cfg.sensors}
        samples = [s for s in stream if s.sensor in names]
        per: dict[str, float] = {}
        total = math.inf
        for _ in range(max(repeat // 2, 1)):
            core = FusionCore(cfg)
            spent: dict[str, float] = {}
            t_all = clock()
            for smp in samples:
                t0 = clock()
                if core.ingest(smp).publish:
                    core.pose()
                spent[smp.sensor] = spent.get(smp.sensor, 0.0) + clock() - t0
            total = min(total, clock() - t_all)
            counts: dict[str, int] = {}
            for smp in samples:
                counts[smp.sensor] = counts.get(smp.sensor, 0) + 1
            for name, v in spent.items():
                per[name] = min(per.get(name, math.inf), v / counts[name] * 1e6)
        out[f"core_{label}_us_per_msg"] = total / len(samples) * 1e6
        for name in ("gps", "pose"):
            if name in per:
                out[f"core_{label}_ingest_{name}_us"] = per[name]
        if label == "odom_imu_only":
            out["core_odom_imu_only_ingest_odom_us"] = per["wheel"]
            out["core_odom_imu_only_ingest_imu_us"] = per["imu"]
    return out


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
    result["sensors"] = bench_sensors(repeat=3 if quick else 5, number=500 if quick else 2000,
                                      seconds=5.0 if quick else 20.0)
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
            lines.append(f"{section:<10} {k:<40} {v:>12,.2f}")
    return "\n".join(lines)
