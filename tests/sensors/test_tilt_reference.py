"""A tilt reference whenever one exists; planar behaviour when none does.

With ``orientation = "off"`` and nothing else observing tilt, the gyro's x/y biases would
integrate into tens of degrees of tilt and metres of z on a flat floor. The simulated robot drives on
flat ground for 60 s at 1 m/s with turns of up to 0.3 rad/s (centripetal 0.3 m/s^2,
which uncompensated would read as 0.03 rad of roll), and its gyro has x/y biases
of 0.01 rad/s: 0.6 rad of tilt after 60 s if nothing corrects it.
"""

from __future__ import annotations

import math

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot

from tests.support.sim_rest import RestWorld, Segment, simulate
from tests.support.core_samples import make_config

BIAS = (0.01, -0.01, 0.002)
DRIVE = [Segment(2.0)] + [Segment(9.5, speed=1.0, yaw_rate=w) for w in (0.3, -0.2, 0.1, 0.0, -0.3, 0.2)]


def _core(extra: str = "") -> FusionCore:
    return FusionCore(make_config("off", extra_imu=extra))


def _worst_tilt_and_z(core: FusionCore, world: RestWorld) -> tuple[float, float]:
    tilt = z = 0.0
    for s in simulate(world):
        step = core.ingest(s)
        if step.publish and s.stamp > 1001.0:
            _, x = core.pose()
            r, p, _ = rot.to_rpy(tuple(x[3:7].tolist()))
            tilt = max(tilt, abs(r), abs(p))
            z = max(z, abs(float(x[2])))
    return tilt, z


def test_gravity_gives_roll_and_pitch_when_the_imu_gives_no_orientation():
    # no standstill: the x/y biases cannot be learned at rest, only through gravity. The robot
    # starts off at 0.25 m/s^2 (4 s to 1 m/s), which the accelerometer feels: removed with the
    # slope of the odometry's speed, skipped where the acceleration changes (its first samples)
    world = RestWorld(list(DRIVE[1:]), gyro_bias=BIAS, accel_sigma=0.05, orientation_absent=True, ramp_s=4.0)
    core = _core()
    tilt, z = _worst_tilt_and_z(core, world)
    # accelerometer noise 0.05 m/s^2 is 0.005 rad of tilt per sample at 100 Hz; the centripetal
    # term is removed; what remains is the lag behind the x/y bias (observable through
    # gravity, so learned): well under 0.02 rad (against 0.6 rad uncorrected).
    assert tilt < 0.02
    # z grows at most by speed x sin(tilt) x time: 1 m/s x 0.02 x 60 s = 1.2 m
    assert z < 1.2
    assert core.tilt_reference


def test_without_any_tilt_reference_the_robot_is_planar():
    world = RestWorld(list(DRIVE), gyro_bias=BIAS, orientation_absent=True)  # no accelerometer either
    core = _core("tilt_from_gravity = false")
    assert not core.tilt_reference
    tilt, z = _worst_tilt_and_z(core, world)
    assert tilt < 1e-9 and z < 1e-9  # roll/pitch rates are not integrated: nothing tilts


def test_centripetal_acceleration_is_not_read_as_roll():
    """A steady 0.3 rad/s turn at 1 m/s: the accelerometer reads 0.3 m/s^2 sideways. Read as
    gravity that is atan(0.3 / 9.81) = 0.031 rad of roll; compensated, the roll stays at noise."""
    world = RestWorld([Segment(1.0), Segment(20.0, speed=1.0, yaw_rate=0.3)], accel_sigma=0.02,
                      orientation_absent=True, ramp_s=1.0)
    core = _core()
    tilt, _ = _worst_tilt_and_z(core, world)
    assert tilt < 0.5 * math.atan2(0.3, 9.80665)


def test_forward_acceleration_is_not_read_as_pitch():
    """A car starting off to 5 m/s over 20 s, accelerating to 7.5 m/s over 20 s (0.125 m/s^2), cruising,
    then braking to 2.5 m/s over 20 s (-0.25 m/s^2) on a flat road: read as gravity that is atan(a / g) = 0.0127 and 0.0255
    rad of pitch, and at 5-7.5 m/s 0.0255 rad of pitch climbs 0.13-0.19 m of z a second. Removed with
    the slope of the odometry's speed (noise 0.01 m/s at 50 Hz: ~0.015 m/s^2 over 0.5 s, 0.0015 rad),
    the pitch stays within a quarter of the smaller uncompensated value, and z within what that
    leaves over the 85 s (7.5 m/s x 0.0032 rad x 70 s = 1.7 m; 6-13 m before)."""
    world = RestWorld([Segment(20.0, speed=5.0), Segment(20.0, speed=7.5), Segment(25.0, speed=7.5),
                       Segment(20.0, speed=2.5)], accel_sigma=0.02, orientation_absent=True, ramp_s=20.0)
    core = _core()
    tilt, z = _worst_tilt_and_z(core, world)
    assert tilt < 0.25 * math.atan2(0.125, 9.80665)
    assert z < 1.7


def test_the_summary_says_when_the_robot_is_taken_as_planar():
    from fusiond.replay.run import run_samples, summary

    world = RestWorld([Segment(1.0), Segment(3.0, speed=1.0)], orientation_absent=True)
    cfg = _core("tilt_from_gravity = false").cfg
    assert "taken as planar" in summary(run_samples(simulate(world), cfg))
    world = RestWorld([Segment(1.0), Segment(3.0, speed=1.0)], accel_sigma=0.05, orientation_absent=True)
    assert "taken as planar" not in summary(run_samples(simulate(world), _core().cfg))


def test_an_accelerometer_reporting_in_g_still_gives_the_tilt():
    # no standstill (x/y biases unlearned): only gravity keeps the tilt down; unrecognised g units
    # would leave 5 s of 0.01 rad/s drift before the planar fallback, 0.05 rad
    world = RestWorld(list(DRIVE[1:]), gyro_bias=BIAS, accel_sigma=0.05, orientation_absent=True,
                      accel_scale=1.0 / 9.80665)
    tilt, _ = _worst_tilt_and_z(_core(), world)
    assert tilt < 0.02  # as with m/s^2 (first test): the g units are recognised


def test_a_configured_tilt_reference_that_gives_nothing_falls_back_to_planar():
    """The accelerometer publishes acceleration with gravity removed: no sample passes the
    low-dynamics gate, so no roll/pitch information arrives. After TILT_STALE_S (5 s) of that
    the roll/pitch rates are no longer integrated: the x/y biases (0.01 rad/s) tilt the robot
    by at most 0.01 x 5 s = 0.05 rad per axis, not 0.6 rad."""
    # no standstill: the x/y biases are not learned either (at rest they would be, and cancel)
    world = RestWorld(list(DRIVE[1:]), gyro_bias=BIAS, accel_sigma=0.05, orientation_absent=True,
                      accel_gravity_removed=True)
    core = _core()
    assert core.tilt_reference  # configured: tilt_from_gravity with an accelerometer
    tilt, _ = _worst_tilt_and_z(core, world)
    assert tilt < 0.01 * 5.0 * math.sqrt(2) + 0.01


def test_engine_vibration_is_not_read_as_a_tilt():
    """A car at 25 m/s on a level road, its accelerometer (400 Hz, no orientation) shaken by 4 m/s^2 at 33 Hz on
    every axis in phase (an engine). Sample by sample, atan2 and the magnitude gate turn that zero-mean
    vibration into a steady ~0.2 deg of roll and pitch: 6 m of z over 1.5 km. Averaged over GRAVITY_AVERAGE_S
    first, a window holds 3.3 periods: what is left of the sinusoid in one is at most 4 x sin(0.3 pi) /
    (3.3 pi) = 0.31 m/s^2 (0.03 rad) with a phase that varies from window to window, so it averages away in
    the filter. Asserted: mean roll and pitch over the last 50 s under 0.1 deg, and |z| after 60 s under the
    0.1 deg x 1.5 km = 2.6 m that bound allows (3 m)."""
    import numpy as np

    from fusiond.core.sensors import ImuSample, OdomSample

    rng = np.random.default_rng(1)
    core = _core()
    wcov = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    gcov, acov = (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6), (0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01)
    tilts = []
    for k in range(60 * 400):
        t = 100.0 + k / 400.0
        vib = 4.0 * math.sin(2.0 * math.pi * 33.0 * k / 400.0 + 0.3)
        accel = (vib + rng.normal(0, 0.05), vib + rng.normal(0, 0.05), 9.80665 + vib + rng.normal(0, 0.05))
        core.ingest(ImuSample("imu", t, (0.0, 0.0, 0.0, 0.0), (-1.0,) + (0.0,) * 8, tuple(rng.normal(0, 0.001, 3)),
                              gcov, accel, acov))
        if k % 20 == 0:
            core.ingest(OdomSample("wheel", t, (25.0, 0.0, 0.0), (0.0, 0.0, 0.0), wcov))
        if k % 400 == 0 and t > 110.0:
            r, p, _ = rot.to_rpy(tuple(core.pose()[1][3:7].tolist()))
            tilts.append((r, p))
    roll, pitch = np.degrees(np.mean(tilts, axis=0))
    assert abs(roll) < 0.1 and abs(pitch) < 0.1, (roll, pitch)
    assert abs(float(core.pose()[1][2])) < 3.0
