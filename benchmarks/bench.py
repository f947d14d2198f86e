"""`fusiond bench`: the numbers the closing notes report, measured the same way each time.

- estimator: predict + roll/pitch update of the gyro-bias model, us per step
  (min over repeats: the machine's quietest moment, not its average), on the compiled
  backend when built and, beside it, on the numpy reference;
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

import math
import os
import re
import statistics
import subprocess
import sys
import time
import timeit
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fusiond.config import Config

# In-process timings are CPU time of this thread, not wall time: on a shared machine other
# processes' load stretches wall time but not the work this thread does (both sides of a
# ratio are timed alike). Whole-process runs report wall time and the child's CPU time.
CLOCK = time.thread_time


def _backend():
    """The estimator's backend the cores here run, as `fusiond` takes it (FUSIOND_KERNELS)."""
    from fusiond.estimator.backend import from_environment

    return from_environment(os.environ)


def _best_us(fn: Callable[[], object], number: int, repeat: int) -> float:
    return min(timeit.Timer(fn, timer=CLOCK).repeat(repeat=repeat, number=number)) / number * 1e6


def estimator_model(backend=None):
    """The model ``bench_estimator`` times and ``tight_step`` mirrors (tests hold the two together):
    pose + gyro bias, driving a circle at 0.5 m/s with a gyro, a roll/pitch update masked to tilt and
    the x/y bias. Returns a namespace: layout, ws (the prediction workspace, as FusionCore holds one),
    ekf (on ``backend``; None: the default), u, noise, cov (the update's covariance), mask."""
    from types import SimpleNamespace

    from fusiond.estimator import (DEFAULT_BACKEND, ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock,
                                   PredictWorkspace, StateLayout)

    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    u = MotionInput()
    u.linear, u.angular = (0.5, 0.0, 0.0), (0.01, -0.02, 0.2)
    u.linear_cov = (1e-3, 0, 0, 0, 1e-3, 0, 0, 0, 1e-3)
    u.angular_cov = (2.5e-5, 0, 0, 0, 2.5e-5, 0, 0, 0, 2.5e-5)
    u.linear_period = u.angular_period = 0.02
    u.from_gyro = True
    mask = np.ones(layout.error_dim, dtype=bool)
    mask[[0, 1, 2, 5, 8]] = False
    ekf = ErrorStateEKF(layout, backend=DEFAULT_BACKEND if backend is None else backend)
    return SimpleNamespace(layout=layout, ws=PredictWorkspace(layout), ekf=ekf, u=u,
                           noise=layout.noise_density(np.full(6, 4e-6)), cov=(1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6),
                           mask=mask)


def bench_estimator(repeat: int = 7, number: int = 3000) -> dict[str, float]:
    """us per predict, per update and per step (predict + update) of ``estimator_model``, with the
    compiled backend when built and on the numpy reference. The steps are timed interleaved
    with the yardstick (``tight_step``), a repeat of each in turn, so that a load spike on this shared
    machine slows both sides of the ratio alike; ``step_vs_tight_median`` is the median of the
    per-repeat ratios, the figure least moved by one noisy repeat."""
    from fusiond.estimator import DEFAULT_BACKEND, PYTHON_BACKEND

    predict_only, update_only, step = _estimator_steps(estimator_model())

    def best(fn) -> float:
        return _best_us(fn, number, repeat)

    compiled = DEFAULT_BACKEND is not PYTHON_BACKEND
    reference_step = _estimator_steps(estimator_model(PYTHON_BACKEND))[2]
    out = {"kernels_compiled": float(compiled), "predict_us": best(predict_only), "update_us": best(update_only)}
    tight = tight_step()
    timer = {name: timeit.Timer(fn, timer=CLOCK) for name, fn in (("step", step), ("tight", tight))}
    runs: dict[str, list[float]] = {"step": [], "tight": [], "numpy": []}
    for _ in range(repeat):
        for name in ("step", "tight"):
            runs[name].append(timer[name].timeit(number) / number * 1e6)
        if compiled:  # the reference backend's same step, for the before/after
            runs["numpy"].append(timeit.Timer(reference_step, timer=CLOCK).timeit(number) / number * 1e6)
    out["predict_update_us"] = min(runs["step"])
    out["tight_numpy_step_us"] = min(runs["tight"])
    out["step_vs_tight_median"] = statistics.median(a / b for a, b in zip(runs["step"], runs["tight"]))
    if runs["numpy"]:
        out["predict_update_numpy_us"] = min(runs["numpy"])
    return out


def _estimator_steps(m) -> tuple[Callable[[], None], Callable[[], None], Callable[[], None]]:
    """(predict, update, both) of ``estimator_model`` ``m``, on its filter's backend."""
    from fusiond.estimator import observations as obs

    layout, ws, ekf, u, noise, cov, mask = m.layout, m.ws, m.ekf, m.u, m.noise, m.cov, m.mask
    backend = ekf.backend

    def predict_only() -> None:
        x, F, Q = backend.predict(layout, ekf.x, u, 0.01, noise, ws)
        ekf.propagate(x, F, Q)

    def update_only() -> None:
        y, H, R = obs.orientation(layout, ekf.x, (0.001, -0.002, 0.0), cov, (0, 1), backend)
        ekf.update(y, H, R, mask=mask)

    def step() -> None:
        predict_only()
        update_only()

    return predict_only, update_only, step


def tight_step(dt: float = 0.01) -> Callable[[], None]:
    """A tight numpy step of the estimator's model, as a careful user would write it for this one
    layout (p, q, gyro bias: 9 error states) and these inputs: body twist and gyro minus bias
    drive the pose (3x3 algebra on floats), F's two changing blocks written into a preallocated F,
    isotropic input noise added on Q's diagonal, P = F P F^T + Q, then the masked roll/pitch update
    with H on the two attitude columns and a closed-form 2x2 Cholesky. The yardstick of
    `bench_estimator`: the same maths, none of the generality (layouts, input blocks, gating,
    diagnostics, covariance checks)."""

    from fusiond.estimator import rotation as rot

    wx, wy, wz = 0.01, -0.02, 0.2
    period = 0.02
    sig_v, sig_w = 1e-3, 2.5e-5  # isotropic input variances (per message, held for `period`)
    noise = np.full(9, 4e-6)
    noise[6:9] = 2e-5**2
    q_diag = np.arange(9) * 10  # flat indices of the diagonal
    q_noise = noise * dt
    q_noise[0:3] += sig_v * dt * period  # G Sigma G^T T/dt with G = R dt: sigma^2 dt T
    q_noise[3:6] += sig_w * dt * period
    st: dict = {"p": (0.0, 0.0, 0.0), "q": (0.0, 0.0, 0.0, 1.0), "b": (0.0, 0.0, 0.0),
                "P": np.diag([0.0] * 3 + [0.01] * 3 + [1e-4] * 3)}
    F = np.eye(9)
    Q = np.zeros((9, 9))
    Hs = np.zeros((2, 2))
    keep = np.ones(9)
    keep[[0, 1, 2, 5, 8]] = 0.0  # roll/pitch may move roll, pitch and the x/y bias only
    weights = 1.0 - np.outer(1.0 - keep, 1.0 - keep)
    z_rp = (0.001, -0.002)

    def step() -> None:
        qx, qy, qz, qw = st["q"]
        bx, by, bz = st["b"]
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = rot.matrix9((qx, qy, qz, qw))
        dpx, dpy, dpz = 0.5 * r0 * dt, 0.5 * r3 * dt, 0.5 * r6 * dt  # R (0.5, 0, 0) dt
        p = st["p"]
        st["p"] = (p[0] + dpx, p[1] + dpy, p[2] + dpz)
        q1 = rot.normalize(rot.mul((qx, qy, qz, qw), rot.exp((wx - bx) * dt, (wy - by) * dt, (wz - bz) * dt)))
        R1 = rot.matrix9(q1)
        F[0:3, 3:6] = ((0.0, dpz, -dpy), (-dpz, 0.0, dpx), (dpy, -dpx, 0.0))
        F[3:6, 6:9] = ((-R1[0] * dt, -R1[1] * dt, -R1[2] * dt), (-R1[3] * dt, -R1[4] * dt, -R1[5] * dt),
                       (-R1[6] * dt, -R1[7] * dt, -R1[8] * dt))  # Jr ~ I for a 2 mrad step
        Q.flat[q_diag] = q_noise
        P = np.dot(np.dot(F, st["P"]), F.T)
        P += Q
        x, y, z, w = q1
        roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
        yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        c, s = math.cos(yaw), math.sin(yaw)
        Hs[0, 0], Hs[0, 1], Hs[1, 0], Hs[1, 1] = c, s, -s, c  # global x/y tilt seen through the heading
        PHt = np.dot(P[:, 3:5], Hs.T)
        (s00, s01), (s10, s11) = np.dot(Hs, PHt[3:5]).tolist()
        a00 = math.sqrt(s00 + 1e-6)
        l10 = s10 / a00
        l11 = math.sqrt(s11 + 1e-6 - l10 * l10)
        i00, i11 = 1.0 / a00, 1.0 / l11
        i10 = -l10 * i00 * i11
        e0, e1 = z_rp[0] - roll, z_rp[1] - pitch
        W = np.dot(((i00, 0.0), (i10, i11)), PHt.T)
        dx = np.dot((i00 * e0, i10 * e0 + i11 * e1), W)
        C = np.dot(W.T, W)
        C *= weights
        P -= C
        st["P"] = P
        d = dx.tolist()  # masked: position, yaw and z bias rows of the gain are zero
        st["q"] = rot.normalize(rot.mul(rot.exp(d[3], d[4], 0.0), q1))
        st["b"] = (bx + d[6], by + d[7], bz)

    return step


def bench_sensors(repeat: int = 5, number: int = 2000, seconds: float = 20.0) -> dict[str, float]:
    """us per update of the GPS and pose sensors (estimator level, then through the core)."""

    from fusiond.config import loads
    from fusiond.core.fusion import FusionCore
    from fusiond.estimator import (ErrorStateEKF, GyroBiasBlock, GyroScaleBlock, PoseBlock, StateLayout,
                                   WheelScaleBlock)
    from fusiond.estimator import observations as obs
    from fusiond.estimator import rotation as rot
    from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic
    from fusiond.core.sensors.pose import PoseSample
    from fusiond.core.sensors import GpsSample, ImuSample, OdomSample

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
        return _best_us(fn, number, repeat)

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
    clock = CLOCK
    for label, text in configs.items():
        cfg = loads(text)
        names = {s.name for s in cfg.sensors}
        samples = [s for s in stream if s.sensor in names]
        per: dict[str, float] = {}
        total = math.inf
        for _ in range(max(repeat // 2, 1)):
            core = FusionCore(cfg, _backend())
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
    """In-process replay (bag reading, decoding, the core and the doctor: `replay.run.replay`) beside
    rosbags' own reading and deserialising of the same bag, and where the replay's time goes.
    Each side is timed in turn, a repeat of each, so that a load spike on this shared machine
    slows all alike; ``replay_vs_rosbags`` is the ratio of the best rates, ``replay_vs_rosbags_median``
    the median of the per-repeat ratios. The split, per message: ``read_decode_us`` (the bag read
    into samples, `open_bag_samples`), ``core_us`` (those samples through `FusionCore` alone),
    ``no_doctor_us`` (the replay a ``--quiet`` run makes: no doctor) and ``replay_us``; the replay's
    rate with a core that cost nothing, ``replay_vs_rosbags_core_free``, bounds what a faster core
    alone can reach."""
    from rosbags.highlevel import AnyReader

    from fusiond.core.fusion import FusionCore
    from fusiond.replay.bag import open_bag_samples
    from fusiond.replay.run import replay

    topics = {"/" + s.key for s in cfg.sensors}

    def rosbags_decode() -> int:
        n = 0
        with AnyReader([bag]) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for conn, _, raw in reader.messages(connections=conns):
                reader.deserialize(raw, conn.msgtype)
                n += 1
        return n

    def read() -> list:
        with open_bag_samples([bag], cfg.sensors) as b:
            return list(b)

    def timed(fn) -> tuple[float, object]:
        t0 = CLOCK()
        out = fn()
        return CLOCK() - t0, out

    samples = read()

    backend = _backend()

    def fuse() -> None:
        core = FusionCore(cfg, backend)
        for s in samples:
            if core.ingest(s).publish:
                core.pose()

    sides = {
        "rosbags": rosbags_decode,
        "read_decode": read,
        "core": fuse,
        "no_doctor": lambda: replay([bag], cfg, keep_trace=False, progress=False, doctor=False, backend=backend),
        "replay": lambda: replay([bag], cfg, keep_trace=False, progress=False, backend=backend),
    }
    runs: dict[str, list[float]] = {k: [] for k in sides}
    n = 0
    for _ in range(max(repeat, 1)):
        for name, fn in sides.items():
            seconds, out = timed(fn)
            runs[name].append(seconds)
            if name == "rosbags":
                n = int(out)
    m = len(samples)
    best = {k: min(v) for k, v in runs.items()}
    rate = m / best["replay"]
    rosbags_rate = n / best["rosbags"]
    free = best["replay"] - best["core"]  # the replay's other work: reading, decoding, the doctor
    return {
        "messages": float(n),
        "rosbags_decode_msg_s": rosbags_rate,
        "rosbags_us_per_msg": best["rosbags"] / n * 1e6,
        "read_decode_us_per_msg": best["read_decode"] / m * 1e6,
        "core_us_per_msg": best["core"] / m * 1e6,
        "no_doctor_us_per_msg": best["no_doctor"] / m * 1e6,
        "replay_us_per_msg": best["replay"] / m * 1e6,
        "replay_in_process_msg_s": rate,
        "replay_vs_rosbags": rate / rosbags_rate,
        "replay_vs_rosbags_median": statistics.median(
            (m / p) / (n / r) for r, p in zip(runs["rosbags"], runs["replay"])),
        "replay_no_doctor_vs_rosbags": (m / best["no_doctor"]) / rosbags_rate,
        "replay_vs_rosbags_core_free": (m / free) / rosbags_rate if free > 0 else math.inf,
    }


def _run_child(cmd: list[str]) -> tuple[float, float]:
    """(wall s, CPU s of the child: user + system) of one command run to completion."""
    import os

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.stderr:
        proc.stderr.close()
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[:4]} failed ({proc.returncode}): {err[-500:]}")
    return wall, usage.ru_utime + usage.ru_stime


def _compile_package() -> None:
    """Byte-compile fusiond's own modules first, as `pip install` does for the installed package
    (and so for the Docker image) and as numpy and rosbags already are in site-packages. Without
    it, an editable checkout run with PYTHONDONTWRITEBYTECODE=1 (the Dockerfile sets it; so do
    CI shells) recompiles all ~60 modules in every `fusiond replay` process (~80 ms of CPU here):
    a cost of the checkout, not of fusiond. The bare script is a script either way (CPython never
    caches `__main__`)."""
    import compileall

    import fusiond

    compileall.compile_dir(str(Path(fusiond.__file__).resolve().parent), quiet=1)


def bench_process(bag: Path, config: Path, topics: tuple[str, str], repeat: int = 3,
                  label: str = "") -> dict[str, float]:
    """Whole `fusiond replay` process beside the bare numpy script on the same bag, alternated so
    that both see the same load; medians of wall time and of the child's CPU time."""
    root = Path(__file__).resolve().parents[1]
    bare = root / "scripts" / "bare_ekf_replay.py"
    _compile_package()
    fusiond_cmd = [sys.executable, "-m", "fusiond", "replay", str(bag), "--config", str(config), "--quiet"]
    bare_cmd = [sys.executable, str(bare), str(bag), *topics]
    runs: dict[str, list[tuple[float, float]]] = {"fusiond": [], "bare": []}
    for _ in range(repeat):
        runs["fusiond"].append(_run_child(fusiond_cmd))
        if bare.is_file():
            runs["bare"].append(_run_child(bare_cmd))
    sfx = f"_{label}" if label else ""
    out = {f"fusiond_replay{sfx}_s": statistics.median(w for w, _ in runs["fusiond"]),
           f"fusiond_replay{sfx}_cpu_s": statistics.median(c for _, c in runs["fusiond"])}
    if runs["bare"]:
        out[f"bare_numpy_script{sfx}_s"] = statistics.median(w for w, _ in runs["bare"])
        out[f"bare_numpy_script{sfx}_cpu_s"] = statistics.median(c for _, c in runs["bare"])
    return out


def write_synthetic_bag(path: Path, odom_topic: str, imu_topic: str, messages: int = 15_000) -> Path:
    """A ROS 2 bag of a robot driving a circle: odometry 50 Hz, IMU 100 Hz (5 ms behind), ``messages``
    in all, through the codecs' own CDR encoders (what a live publisher puts on the wire)."""

    from rosbags.rosbag2 import Writer

    from fusiond.estimator import rotation as rot
    from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
    from fusiond.codecs import IMU, ODOMETRY, TYPESTORE

    cov36 = tuple(1e-3 if i % 7 == 0 else 0.0 for i in range(36))
    ocov = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
    gcov = (2.5e-5, 0.0, 0.0, 0.0, 2.5e-5, 0.0, 0.0, 0.0, 2.5e-5)
    with Writer(path, version=9) as writer:
        odom = writer.add_connection(odom_topic, ODOMETRY, typestore=TYPESTORE)
        imu = writer.add_connection(imu_topic, IMU, typestore=TYPESTORE)
        n = k = 0
        while n < messages:
            t = 1000.0 + 0.01 * k
            if k % 2 == 0:
                writer.write(odom, int(t * 1e9), encode_sample(
                    OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.2), cov36), "ros2-cdr"))
                n += 1
            if n < messages:
                ti = t + 0.005
                q = rot.from_rpy(0.01 * math.sin(ti), -0.01 * math.cos(ti), 0.2 * (ti - 1000.0))
                writer.write(imu, int(ti * 1e9), encode_sample(
                    ImuSample("imu", ti, q, ocov, (0.0, 0.0, 0.2), gcov), "ros2-cdr"))
                n += 1
            k += 1
    return path


def targets(result: dict[str, dict[str, float]]) -> dict[str, float]:
    """The performance ratios, each against its yardstick from the same run (targets in the names)."""
    out: dict[str, float] = {}
    est, yard = result.get("estimator", {}), result.get("yardstick", {})
    if est and yard:
        out["estimator_step_vs_tight_numpy (<=1.5)"] = est["predict_update_us"] / yard["tight_numpy_step_us"]
        if "step_vs_tight_median" in est:
            out["estimator_step_vs_tight_numpy_median_of_pairs (<=1.5)"] = est["step_vs_tight_median"]
    rep = result.get("replay", {})
    if rep:
        out["replay_in_process_vs_rosbags_decode (>=0.5)"] = rep["replay_vs_rosbags"]
        if "replay_vs_rosbags_median" in rep:
            out["replay_in_process_vs_rosbags_decode_median_of_pairs (>=0.5)"] = rep["replay_vs_rosbags_median"]
    proc = result.get("process", {})
    for sfx in ("", "_synthetic"):
        f, b = proc.get(f"fusiond_replay{sfx}_s"), proc.get(f"bare_numpy_script{sfx}_s")
        if f and b:
            name = "jackal" if not sfx else "synthetic_15k"
            out[f"replay_process_vs_bare_{name}_wall (<=1.0)"] = f / b
            out[f"replay_process_vs_bare_{name}_cpu (<=1.0)"] = (proc[f"fusiond_replay{sfx}_cpu_s"]
                                                                 / proc[f"bare_numpy_script{sfx}_cpu_s"])
    lat = result.get("latency", {})
    if "cpu_ratio" in lat:
        out["daemon_cpu_vs_bare_subscriber (<=2.0)"] = lat["cpu_ratio"]
    return out


def run(bag: Path, config: Path, cfg: Config, quick: bool = False) -> dict[str, dict[str, float]]:
    import tempfile

    reps, number = (3, 1000) if quick else (7, 3000)
    est = bench_estimator(repeat=reps, number=number)
    result = {"estimator": est, "yardstick": {"tight_numpy_step_us": est.pop("tight_numpy_step_us")}}
    result["sensors"] = bench_sensors(repeat=3 if quick else 5, number=500 if quick else 2000,
                                      seconds=5.0 if quick else 20.0)
    odom = next(s for s in cfg.sensors if type(s).__name__ == "OdomSensor")
    imu = next((s for s in cfg.sensors if type(s).__name__ == "ImuSensor"), odom)
    topics = ("/" + odom.key, "/" + imu.key)
    result["process"] = {}
    if bag.is_file():
        result["replay"] = bench_replay(bag, cfg, repeat=1 if quick else 3)
        result["process"].update(bench_process(bag, config, topics, repeat=1 if quick else 3))
    with tempfile.TemporaryDirectory(prefix="fusiond-bench-") as tmp:
        synthetic = write_synthetic_bag(Path(tmp) / "synthetic", *topics)
        result["process"].update(bench_process(synthetic, config, topics, repeat=1 if quick else 3,
                                               label="synthetic"))
    result["targets"] = targets(result)
    return result


def format_table(result: dict[str, dict[str, float]]) -> str:
    """One line a figure; a target's line says whether this run met its goal (the goal is in its name)."""
    lines = []
    for section, values in result.items():
        width = max((len(k) for k in values), default=0)
        for k, v in values.items():
            line = f"{section:<10} {k:<{max(width, 52)}} {v:>12,.2f}"
            goal = re.search(r"\((<=|>=)([0-9.]+)\)$", k) if section == "targets" else None
            if goal:
                met = v <= float(goal.group(2)) if goal.group(1) == "<=" else v >= float(goal.group(2))
                line += "  met" if met else "  missed"
            lines.append(line)
    return "\n".join(lines)
