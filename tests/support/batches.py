"""A 1 kHz IMU + 100 Hz odometry burst and the diagnostics records a core makes of it."""

from __future__ import annotations

import math
from collections import Counter

from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample, make_decoder
from fusiond.transport.daemon import sensor_kind

IMU_HZ, ODOM_EVERY, N_IMU = 1000.0, 10, 1500  # 1.5 s of 1 kHz IMU and 100 Hz odometry
W = 0.2  # rad/s: driving a circle at 0.5 m/s


def stream() -> list[tuple[str, bytes]]:
    """(key, CDR) in send order: an IMU sample each ms, an odometry sample half a ms after every 10th."""
    cov3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
    twist_cov = tuple(1e-3 if i % 7 == 0 else 0.0 for i in range(36))
    out = []
    for k in range(N_IMU):
        t = 100.0 + k / IMU_HZ
        yaw = W * (t - 100.0)
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        out.append(("t/imu", encode_sample(ImuSample("imu", t, q, cov3, (0.0, 0.0, W), cov3), "ros2-cdr")))
        if k % ODOM_EVERY == 0:
            out.append(("t/odom", encode_sample(OdomSample("wheel", t + 0.5 / IMU_HZ, (0.5, 0.0, 0.0),
                                                                (0.0, 0.0, W), twist_cov), "ros2-cdr")))
    return out


def identity(r: DiagnosticsRecord) -> tuple:
    return r.sensor, r.channel, r.stamp, r.late


def expected_records(cfg, messages: list[tuple[str, bytes]]) -> Counter:
    """The updates the same samples make in a fusion core of the same config, fed in the same order."""
    core = FusionCore(cfg)
    by_key = {s.key: make_decoder(sensor_kind(s), s.encoding, s.name) for s in cfg.sensors}
    out: Counter = Counter()
    for key, raw in messages:
        out.update(identity(r) for r in core.ingest(by_key[key](raw)).records)
    return out
