"""Lost samples sent as zeros are kept out of the doctor's fits (``doctor/lost.py``)."""

from __future__ import annotations

import math

import msgspec
import pytest

from fusiond.doctor.lost import LostSamples
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config
from tests.support.sim_mount import MountWorld, simulate as simulate_mount
from tests.support.verdicts import MOUNT_TOLERANCE_RAD, one, vector, verdicts_of

COV36 = (0.0,) * 36
NO_ORIENTATION = (-1.0,) + (0.0,) * 8


def _odom(t: float, v: float) -> OdomSample:
    return OdomSample("wheel", t, (v, 0.0, 0.0), (0.0, 0.0, 0.1 * v), COV36)


def _admitted(samples) -> list:
    lost = LostSamples()
    out = [s for x in samples for s in lost.admit(x)]
    lost.flush()
    return out


def test_one_zero_frame_between_moving_ones_is_lost_a_lasting_zero_is_not():
    # 2 m/s at 50 Hz, one frame at zero: 100 m/s^2 each way, and the next frame moves again
    frames = [_odom(1.0 + 0.02 * k, 0.0 if k == 5 else 2.0) for k in range(10)]
    assert [s.stamp for s in _admitted(frames)] == [s.stamp for k, s in enumerate(frames) if k != 5]
    # the drive reads zero for 10 frames (a coast): every one is kept
    coast = [_odom(1.0 + 0.02 * k, 0.0 if 5 <= k < 15 else 2.0) for k in range(20)]
    assert _admitted(coast) == coast
    # a stop over half a second (4 m/s^2), then zeros: kept, whatever follows
    stop = [_odom(1.0 + 0.02 * k, max(2.0 - 0.08 * k, 0.0)) for k in range(30)] + [_odom(1.62, 2.0)]
    assert _admitted(stop) == stop
    # the stream ending on such a frame: nothing after it makes it a coast, and no vehicle stops so fast
    assert _admitted(frames[:6]) == frames[:5]


def test_an_imu_sample_of_zeros_without_orientation_is_lost_one_with_orientation_is_not():
    blank = ImuSample("imu", 1.0, (0.0, 0.0, 0.0, 1.0), NO_ORIENTATION, (0.0, 0.0, 0.0), (1e-6,) * 9,
                      (0.0, 0.0, 0.0), (1e-4,) * 9)
    attitude_only = msgspec.structs.replace(blank, orientation_covariance=(1e-4,) * 9)
    moving = msgspec.structs.replace(blank, linear_acceleration=(0.0, 0.0, 9.8))
    lost = LostSamples()
    assert lost.admit(blank) == [] and lost.imu == 1
    assert lost.admit(attitude_only) == [attitude_only] and lost.admit(moving) == [moving]


def _with_lost(samples: list, every_odom: int, every_imu: int) -> list:
    """Every n-th odometry frame sent as zeros (covariance zeros), every m-th IMU sample all zeros."""
    out, k_odom, k_imu = [], 0, 0
    for s in samples:
        if isinstance(s, OdomSample):
            k_odom += 1
            if k_odom % every_odom == 0:
                s = msgspec.structs.replace(s, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0), twist_covariance=COV36)
        elif isinstance(s, ImuSample):
            k_imu += 1
            if k_imu % every_imu == 0:
                s = msgspec.structs.replace(s, angular_velocity=(0.0, 0.0, 0.0), linear_acceleration=(0.0, 0.0, 0.0),
                                            orientation_covariance=NO_ORIENTATION)
        out.append(s)
    return out


def test_the_mounting_is_named_through_lost_frames_and_samples():
    """An IMU turned 90 degrees, no orientation, the wheels' speed swinging 0-2 m/s: 1 odometry frame in
    100 and 1 IMU sample in 200 lost as zeros (at 2 m/s a lost frame is a dv/dt of 100 m/s^2 in and out;
    in a 0.2 s bin, 10 m/s^2 of false acceleration against the 0.4 m/s^2 the fit works with). The
    verdict is the one the clean stream gets: the same turn, within the mounting tolerance, and a fit
    as tight (its 1 s bins average 49 of 50 frames; a lost frame left in would put a step of
    24 m/s / 1 s in its bin's dv/dt, against a clean residual of ~0.02 m/s^2)."""
    world = MountWorld(duration=60.0, speed=12.0, turn=0.1, imu_mount_rpy=(0.0, 0.0, math.pi / 2),
                       orientation_absent=True)
    clean = simulate_mount(world)
    cfg = robot_config(orientation="off")
    residual = []
    for samples in (clean, _with_lost(clean, 100, 200)):
        v = one(verdicts_of(cfg, samples), "imu", "attitude")
        assert v.level == "problem" and v.key == "sensors.imu.extrinsic_rpy", v
        assert vector(v.suggestion) == pytest.approx([0.0, 0.0, math.pi / 2], abs=MOUNT_TOLERANCE_RAD)
        residual.append(v.evidence["mount_residual_rms"])
    assert residual[1] <= 1.5 * residual[0]
