"""Pose collection and the synthetic payloads of the reliability tests."""

from __future__ import annotations

import math
import threading
import time

import zenoh

from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
from fusiond.codecs import decode_pose_cdr, DecodeError

WHEEL_KEY = "jackal_velocity_controller/odom"
IMU_KEY = "imu/data"


class Poses:
    """Published poses (decoded on arrival) with their wall arrival time."""

    def __init__(self, session: zenoh.Session, key: str = "odom_combined") -> None:
        self.items: list[tuple[float, float, tuple[float, ...], tuple[float, ...]]] = []
        self.undecodable = 0
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(key, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            msg = decode_pose_cdr(sample.payload.to_bytes())
        except DecodeError:
            self.undecodable += 1
            return
        st = msg.header.stamp
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        with self.lock:
            self.items.append((now, st.sec + st.nanosec * 1e-9, (p.x, p.y, p.z, q.x, q.y, q.z, q.w),
                               tuple(msg.pose.covariance.tolist())))

    def __len__(self) -> int:
        return len(self.items)

    def stamps(self) -> list[float]:
        with self.lock:
            return [s for _, s, _, _ in self.items]

    def non_finite(self) -> int:
        with self.lock:
            return sum(not all(map(math.isfinite, (*x, *c))) for _, _, x, c in self.items)


def _cov_diag(n: int, values: list[float]) -> tuple[float, ...]:
    c = [0.0] * (n * n)
    for i, v in enumerate(values):
        c[(n + 1) * i] = v
    return tuple(c)


def odom_payload(stamp: float) -> bytes:
    """Odometry of a robot driving a circle (0.5 m/s, 0.2 rad/s), as CDR."""
    cov = _cov_diag(6, [1e-3, 1e-3, 1e-3, 1e6, 1e6, 1e-2])
    return encode_sample(OdomSample("wheel", stamp, (0.5, 0.0, 0.0), (0.0, 0.0, 0.2), cov), "ros2-cdr")


def imu_payload(stamp: float, t0: float = 1000.0) -> bytes:
    """The IMU of the same robot (level, yaw turning at 0.2 rad/s), as CDR."""
    yaw = 0.2 * (stamp - t0)
    q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return encode_sample(ImuSample("imu", stamp, q, _cov_diag(3, [1e-4, 1e-4, 1e-2]), (0.0, 0.0, 0.2),
                                       _cov_diag(3, [1e-5] * 3)), "ros2-cdr")
