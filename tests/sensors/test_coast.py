"""A drive that drops to exactly zero while the vehicle coasts on (``core/sensors/odom/model.py``).

The worlds are ``sim_rest``'s: a car driving a circle of radius R = v / w, its odometry at
50 Hz reading the true twist plus noise (sigma 0.01), or exactly zero in a segment marked
``odom_reads_zero`` while the car coasts, slowing steadily. Speed changes ramp over 0.5 s
(4 m/s^2 from 2 m/s: a vehicle can do that; the coast's drop from 2 m/s to zero in one 20 ms
message is 100 m/s^2, which none can). The filter takes the coasting car to slow at
coast_decel = 1 m/s^2 (the default); the simulated one slows at DECEL.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.odom import STOP_DECEL_LIMIT
from fusiond.core.sensors import OdomSample

from tests.support.configs import robot_config
from tests.support.sim import arrival_order
from tests.support.sim_rest import T0, RestWorld, Segment, simulate

V, W = 2.0, 0.3  # m/s, rad/s: a circle of radius 6.7 m
RAMP_S = 0.5
DECEL = 0.75  # m/s^2: the simulated car's coasting deceleration


def _fuse(samples, coast_decel: float = 1.0) -> tuple[FusionCore, list[tuple[float, float, float]]]:
    """The core and its pose (t, x, y) after every odometry sample."""
    core = FusionCore(robot_config(odom=f"coast_decel = {coast_decel}"))
    track = []
    for s in samples:
        step = core.ingest(s)
        if step.accepted and isinstance(s, OdomSample):
            t, x = core.pose()
            track.append((t, float(x[0]), float(x[1])))
    return core, track


def _at(track, t: float) -> np.ndarray:
    return np.array(min(track, key=lambda p: abs(p[0] - t))[1:])


def _truth_at(world: RestWorld, t: float) -> np.ndarray:
    return np.array(min(world.truth, key=lambda p: abs(p[0] - t))[1:3])


def _path(track, t0: float, t1: float) -> float:
    """Length of the estimated track between t0 and t1."""
    pts = np.array([p[1:] for p in track if t0 <= p[0] <= t1])
    return float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))


def _coasting_world(coast_s: float) -> RestWorld:
    """Driving the circle for 4 s, coasting for coast_s (slowing at DECEL, still turning), driving again."""
    v_end = V - DECEL * coast_s
    return RestWorld([Segment(4.0, speed=V, yaw_rate=W),
                      Segment(coast_s, speed=v_end, yaw_rate=W, odom_reads_zero=True, ramp_s=coast_s),
                      Segment(2.0, speed=v_end, yaw_rate=W)], ramp_s=RAMP_S)


def test_a_drop_no_vehicle_could_make_is_a_coast():
    """A coast of 2 s, the car slowing from 2 to 0.5 m/s: it covers V T - DECEL T^2 / 2 = 2.5 m. The
    filter, slowing at 1 m/s^2, covers 2 m: 0.5 m short along the arc (the decelerations' difference
    x T^2 / 2), plus the noise (0.01 m/s x 6 s of travel); under 0.6 m. Read as a stop
    (``coast_decel = 0``) the pose waits where the drive went quiet: off by the chord of the coasted
    arc, 2 R sin(w T / 2), 2.48 m."""
    coast_s = 2.0
    world = _coasting_world(coast_s)
    samples = simulate(world)
    end = T0 + 4.0 + coast_s
    covered = V * coast_s - DECEL * coast_s**2 / 2
    chord = 2.0 * (V / W) * math.sin(W * coast_s / 2.0) * covered / (V * coast_s)  # arc of `covered` m
    tracks = {decel: _fuse(samples, decel)[1] for decel in (1.0, 0.0)}
    err_coast = np.linalg.norm(_at(tracks[1.0], end) - _truth_at(world, end))
    err_stop = np.linalg.norm(_at(tracks[0.0], end) - _truth_at(world, end))
    assert err_coast < (1.0 - DECEL) * coast_s**2 / 2 + 0.1
    assert err_stop > 0.9 * chord
    assert _path(tracks[1.0], end - coast_s, end) == pytest.approx(V * coast_s - coast_s**2 / 2, rel=0.05)


def test_a_drive_that_measures_no_yaw_rate_coasts_too():
    """The same 2 s coast, the drive's yaw rate marked not measured (a race car's: the gyro turns the heading):
    the drop to zero is a coast all the same, covering V T - T^2 / 2 within 5 % (it stopped dead)."""
    from tests.support.sim_faults import mark_yaw_rate_unmeasured

    coast_s = 2.0
    samples = mark_yaw_rate_unmeasured(simulate(_coasting_world(coast_s)))
    end = T0 + 4.0 + coast_s
    _, track = _fuse(samples)
    assert _path(track, end - coast_s, end) == pytest.approx(V * coast_s - coast_s**2 / 2, rel=0.05)


def test_the_coast_ends_when_the_speed_has_run_down():
    """A coast of 4 s: slowing at 1 m/s^2 from 2 m/s, the estimate stops after |v| / coast_decel = 2 s,
    having covered v^2 / (2 coast_decel) = 2 m (within 5 %), and stands for the rest of it."""
    coast_s = 4.0
    world = RestWorld([Segment(4.0, speed=V, yaw_rate=W),
                       Segment(coast_s, speed=V, yaw_rate=W, odom_reads_zero=True), Segment(1.0, speed=V)],
                      ramp_s=RAMP_S)
    _, track = _fuse(simulate(world))
    start = T0 + 4.0
    stop_s = V / 1.0
    assert _path(track, start, start + coast_s) == pytest.approx(V**2 / 2.0, rel=0.05)
    assert _path(track, start + stop_s + 0.05, start + coast_s - 0.05) < 0.01  # nothing moves it after


def test_the_coasting_speed_slows_and_grows_uncertain_at_coast_decel():
    """1 s into the coast: the speed is the last measured one less 1 m/s, its variance the last
    measured one plus (coast_decel t)^2 = 1 m^2/s^2."""
    world = _coasting_world(2.0)
    core = FusionCore(robot_config(odom="coast_decel = 1.0"))
    before = None
    for s in simulate(world):
        core.ingest(s)
        if isinstance(s, OdomSample) and s.stamp < T0 + 4.0:
            before = (s.linear[0], core.state.linear_cov[0])
        if isinstance(s, OdomSample) and s.stamp >= T0 + 5.0:
            break
    coast = core.state.own[core.odom_index].coast
    age = core.state.t - coast[0]
    assert age == pytest.approx(1.0, abs=0.02)
    assert core.state.linear[0] == pytest.approx(before[0] - 1.0 * age, rel=1e-9)
    assert core.state.linear_cov[0] == pytest.approx(before[1] + age**2, rel=1e-9)
    assert core.state.still_since is None  # a coast is no standstill: no gyro bias learned in it


def test_a_stop_a_vehicle_can_make_is_a_stop():
    """Braking at 4 m/s^2 (under STOP_DECEL_LIMIT): no coast, and the pose stands from the stop on,
    while the standstill starts counting for the gyro bias."""
    assert 2.0 * V / 1.0 < STOP_DECEL_LIMIT * 1.0  # the ramp's deceleration, 4 m/s^2, is far below the limit
    world = RestWorld([Segment(4.0, speed=V, yaw_rate=W), Segment(3.0)], ramp_s=RAMP_S)
    core, track = _fuse(simulate(world))
    stop = T0 + 4.0 + RAMP_S
    assert _path(track, stop + 0.05, stop + 2.9) < 0.01
    assert core.state.own[core.odom_index].coast is None
    assert core.state.still_since is not None and core.state.still_since <= stop + 0.05


def test_a_skid_steer_turning_on_the_spot_is_not_a_coast():
    """From 1 m/s to turning on the spot in one message (no ramp: the drop in speed alone is 50 m/s^2):
    the wheels read the turn, so the twist is not zero and nothing is held. The pose stays put while
    it spins (its wheel noise, 0.01 m/s x 2 s, at most)."""
    world = RestWorld([Segment(3.0, speed=1.0), Segment(2.0, yaw_rate=1.0)])
    core, track = _fuse(simulate(world))
    assert _path(track, T0 + 3.05, T0 + 4.95) < 0.05
    assert core.state.own[core.odom_index].coast is None


def test_the_coast_is_the_same_whatever_the_arrival_order():
    """The coast lives in the odometry's slice of the state, which the late-data history snapshots:
    samples arriving late (IMU 30 ms behind, jittered) give the same final pose."""
    samples = simulate(_coasting_world(2.0))
    core_a, _ = _fuse(samples)
    core_b, _ = _fuse(arrival_order(samples, {"imu": 0.03}, jitter=0.01, seed=3))
    assert np.allclose(core_a.pose()[1], core_b.pose()[1], atol=1e-9)


@pytest.mark.parametrize("coast_decel", [1.0, 0.0])
def test_the_doctor_says_what_the_position_did_while_the_drive_read_zero(coast_decel: float):
    """No real standstill, one coast through a turn (0.3 rad/s, far beyond the quiet bound
    3 x (0.002 + 0.01) = 0.036 rad/s): the gyro bias verdict names the stretch and says, by
    ``coast_decel``, whether the position ran on or waited."""
    from tests.support.verdicts import one, verdicts_of

    samples = simulate(_coasting_world(2.0))
    v = one(verdicts_of(robot_config(odom=f"coast_decel = {coast_decel}"), samples), "imu", "gyro_bias")
    assert v.evidence["turning_at_rest"] == 1.0, v
    assert "sensors.wheel.coast_decel" in v.message
    if coast_decel > 0.0:
        assert f"ran on from the last speed, slowing at {coast_decel:g} m/s^2 until it stopped" in v.message
    else:
        assert "does not advance while the wheels read zero (sensors.wheel.coast_decel = 0" in v.message


def test_a_coasts_acceleration_is_unknown_to_the_gravity_tilt():
    """Through a coast the forward speed is the assumed slowing at coast_decel, anything from none to twice
    that: its slope is no measurement of the vehicle's acceleration, which an IMU taking roll/pitch from
    gravity would read as 3 deg of pitch per 0.5 m/s^2. ``forward_accel`` says unknown (NaN) there, as where
    the speeds do not fit a line, and the driving either side of it is known again."""
    core = FusionCore(robot_config(orientation="off"))
    odom = core.models[core.odom_index]
    known, coasting = [], []
    for s in simulate(_coasting_world(2.0)):
        step = core.ingest(s)
        if step.accepted and isinstance(s, OdomSample):
            a = odom.forward_accel(core.state)
            (coasting if core.state.own[core.odom_index].coast is not None else known).append(a)
    assert coasting and all(math.isnan(a) for a in coasting), coasting[:5]
    assert sum(math.isfinite(a) for a in known) > 0.8 * len(known)
