"""What `replay --smooth` costs: time and memory of the smoother beside the forward pass it follows.

A benchmark, not a test: it asserts nothing. A robot drives a circle for --seconds of message time with a
1 kHz IMU (gyro and orientation), 100 Hz odometry (the publish moments, so the smoother's anchors) and a
10 Hz GPS; the same samples go through the replay loop (``fusiond.replay.run.Runner``) without and with
smoothing. Printed: the forward pass's CPU time per message both ways (the process's own: other
work on a shared machine moves it less than the wall time), the backward pass's time, the
recorder's bytes per anchor (the arrays it holds: ``SmoothingRecorder.anchors``) and those figures
scaled to an hour of the same rates (an estimate from the measured per-message and per-anchor costs).

    .venv/bin/python scripts/smoother_bench.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import math
import sys
import time

ROOT_HINT = "run from the repository root with its .venv"


def stream(seconds: float) -> list:
    from fusiond.estimator import rotation as rot
    from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic
    from fusiond.core.sensors import GpsSample, ImuSample, OdomSample

    enu = EnuFrame(48.137, 11.575, 520.0)
    cov36 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    gcov = (1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6)
    cov3 = (0.09, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 0.09)
    out: list = []
    for k in range(int(seconds * 1000)):
        t = 1000.0 + 0.001 * k
        yaw = 0.2 * (t - 1000.0)
        out.append(ImuSample("imu", t, rot.from_rpy(0.0, 0.0, yaw), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e6),
                             (0.0, 0.0, 0.2), gcov))
        if k % 10 == 0:
            out.append(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.2), cov36))
        if k % 100 == 0:
            px, py = 5.0 * math.sin(yaw), 5.0 - 5.0 * math.cos(yaw)
            lat, lon, alt = enu_to_geodetic(enu, px, py, 0.0)
            out.append(GpsSample("gps", t, lat, lon, alt, 0, cov3, 2))
    return out


CONFIG = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
orientation = "roll_pitch"
angular_velocity = true
[[sensors]]
name = "gps"
kind = "gps"
key = "gps"
datum = [48.137, 11.575, 520.0]
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="message time simulated (default 60)")
    args = ap.parse_args()
    try:
        from fusiond.config import loads
        from fusiond.replay.run import Runner
    except ImportError:
        print(ROOT_HINT, file=sys.stderr)
        return 2
    cfg = loads(CONFIG)
    samples = stream(args.seconds)
    n = len(samples)
    times = {}
    for smooth in (False, True):
        runner = Runner(cfg, keep_trace=False, doctor=False, smooth=smooth)
        core = runner.core
        t0 = time.process_time()
        for s in samples:
            core.ingest(s)
        times[smooth] = time.process_time() - t0
    t0 = time.process_time()
    sm = core.smoothed()
    backward = time.process_time() - t0
    anchors = core._smoothing.anchors  # the recorder's own list: what the smoother holds
    held = sum(a.x.nbytes + sum(v.nbytes for v in a.link if v is not None) if a.link else a.x.nbytes
               for a in anchors)
    per_anchor = held / max(len(anchors), 1)
    hour = 3600.0 / args.seconds
    print(f"layout: error dimension {core.layout.error_dim}, nominal {core.layout.nominal_dim}")
    print(f"messages {n} over {args.seconds:g} s, anchors {len(anchors)} (smoothed poses {sm.t.size})")
    print(f"forward pass      {1e6 * times[False] / n:8.1f} us/message")
    print(f"forward + record  {1e6 * times[True] / n:8.1f} us/message "
          f"(+{1e6 * (times[True] - times[False]) / n:.1f})")
    print(f"backward pass     {1e6 * backward / max(len(anchors), 1):8.1f} us/anchor ({backward:.2f} s)")
    print(f"recorder          {per_anchor:8.0f} bytes/anchor in arrays, {held / 1e6:.1f} MB")
    print(f"an hour of these rates (scaled): recording +{(times[True] - times[False]) * hour:.0f} s, "
          f"backward {backward * hour:.0f} s, forward {times[False] * hour:.0f} s; "
          f"memory {held * hour / 1e9:.2f} GB in arrays")
    return 0


if __name__ == "__main__":
    sys.exit(main())
