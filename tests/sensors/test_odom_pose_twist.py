"""An odometry whose driver fills the pose only (``twist_from_pose``): the twist from consecutive poses.

Thresholds from the geometry: on a circle of radius r = v / w sampled every dt, the chord between two
poses is 2 r sin(w dt / 2) long and points along the body's x at the middle of the turn, so the twist the
poses imply is (v sinc(w dt / 2), 0, 0) and (0, 0, w): its speed short of v by v (w dt)^2 / 24 at most,
nothing sideways, the yaw rate exact (to rounding).
"""

from __future__ import annotations

import math

import msgspec
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import OdomSample
from fusiond.core.sensors.odom import PoseDifferences
from fusiond.estimator import rotation as rot

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate

V, W, DT = 2.0, 0.5, 0.02


def _circle(n: int, t0: float = 100.0, dt: float = DT) -> list[OdomSample]:
    """Pose-only messages of a robot driving a circle at V, W: the twist left zero, covariance 0."""
    r = V / W
    out = []
    for k in range(n):
        t = t0 + k * dt
        a = W * (t - t0)
        out.append(OdomSample("wheel", t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0,) * 36,
                              (r * math.sin(a), r * (1.0 - math.cos(a)), 0.0), rot.from_rpy(0.0, 0.0, a)))
    return out


def test_the_poses_of_a_circle_give_its_twist_in_the_body() -> None:
    diff = PoseDifferences(gap_s := 0.5)
    out = [diff(s) for s in _circle(200)]
    assert gap_s > DT
    short = V * (W * DT) ** 2 / 24.0
    for s in out[1:]:
        vx, vy, vz = s.linear
        assert V - short * 1.01 <= vx <= V and abs(vy) < 1e-9 and abs(vz) < 1e-12, s.linear
        assert s.angular[0] == pytest.approx(0.0, abs=1e-12) and s.angular[2] == pytest.approx(W, rel=1e-9)
        assert s.twist_covariance == (0.0,) * 36  # the floors, unless twist_noise states it


@pytest.mark.parametrize("case", ["first", "gap", "out_of_order", "no_orientation"])
def test_a_message_with_nothing_to_difference_says_the_twist_is_not_measured(case: str) -> None:
    samples = _circle(5)
    diff = PoseDifferences(0.5)
    if case == "gap":  # a logging gap longer than the filter's gap_s: the mean over it is no twist
        samples[3] = msgspec.structs.replace(samples[3], stamp=samples[2].stamp + 0.6)
        samples = samples[:4]
    elif case == "out_of_order":
        samples[3] = msgspec.structs.replace(samples[3], stamp=samples[2].stamp - 0.001)
        samples = samples[:4]
    elif case == "no_orientation":
        samples[3] = msgspec.structs.replace(samples[3], orientation=(0.0, 0.0, 0.0, 0.0))
        samples = samples[:4]
    out = [diff(s) for s in samples]
    last = out[0] if case == "first" else out[-1]
    assert last.linear == (0.0, 0.0, 0.0) and last.angular == (0.0, 0.0, 0.0)
    assert all(last.twist_covariance[7 * i] == math.inf for i in range(6))
    if case == "out_of_order":  # the one it came after still differences the next
        nxt = diff(msgspec.structs.replace(_circle(5)[4]))
        assert nxt.linear[0] == pytest.approx(V, rel=1e-3)


def _pose_only(samples: list) -> list:
    """The simulation's odometry as a driver that fills the pose only: the pose integrated from its twist (the
    midpoint rule, as a drive's dead reckoning), the twist zeroed."""
    out, x, y, yaw, last = [], 0.0, 0.0, 0.0, None
    for s in samples:
        if not isinstance(s, OdomSample):
            out.append(s)
            continue
        if last is not None:
            dt = s.stamp - last.stamp
            mid = yaw + 0.5 * last.angular[2] * dt
            x += last.linear[0] * math.cos(mid) * dt
            y += last.linear[0] * math.sin(mid) * dt
            yaw += last.angular[2] * dt
        last = s
        out.append(msgspec.structs.replace(s, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0),
                                           position=(x, y, 0.0), orientation=rot.from_rpy(0.0, 0.0, yaw)))
    return out


def _final(samples: list, odom: str) -> tuple[float, float]:
    core = FusionCore(robot_config(odom=odom))
    for s in samples:
        core.ingest(s)
    p = core.state.ekf.position()
    return p[0], p[1]


def test_a_pose_only_drive_moves_the_filter_as_its_twist_would() -> None:
    """60 s of weaving at 1 m/s with the gyro fused: the pose-only driver's poses, differenced, drive the filter to
    where the twist itself drives it. The one-interval lag of a mean over the interval before it telescopes: the
    positions differ by at most the speed's change over one interval times the interval, summed over no more
    than the run's reversals of acceleration; a decimetre bounds it here. Taken as they are (twist zero), the
    robot stays where it started."""
    w = World(duration=60.0, standstill=2.0, speed=1.0, seed=7)
    samples = simulate(w)
    twist = _final(samples, "")
    poses = _pose_only(samples)
    derived = _final(poses, "twist_from_pose = true")
    assert math.dist(twist, (0.0, 0.0)) > 30.0
    assert math.dist(derived, twist) < 0.1, (derived, twist)
    assert math.dist(_final(poses, ""), (0.0, 0.0)) < 0.1
