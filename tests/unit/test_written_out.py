"""The per-message path's shortcuts against the forms they stand for: the held inputs' timeouts (one per
input: the odometry's and the gyro's sensor), the segment end against the expiries, the pose variances
against the published estimate's covariance, ``near_unit`` against ``unit_quaternion``, the written-out
twist covariance against numpy's 6x6."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.core.fusion import FusionCore
from fusiond.core.inputs import next_expiry, silent_after

from tests.support.core_samples import imu, make_config, odom


def _driven(periods: tuple[float, float], n: int) -> FusionCore:
    core = FusionCore(make_config())
    t = 1.0
    for k in range(n):
        core.ingest(odom(t + k * periods[0], v=0.4, w=0.1))
        core.ingest(imu(t + k * periods[1] + 1e-4, gyro=(0.0, 0.0, 0.1)))
    return core


@settings(max_examples=40, deadline=None)
@given(st.floats(0.005, 2.0), st.floats(0.001, 2.0), st.integers(1, 6))
def test_timeouts_are_the_timeout_of_the_odometry_and_of_the_gyro(odom_period, imu_period, n):
    core = _driven((odom_period, imu_period), n)
    s, held = core.state, core.inputs
    odom_timeout, gyro_timeout = held.timeouts(s)
    odom = held.odom_index
    # the odometry's twist holds at least through filter.gap_s (core/inputs.py), beyond its liveness timeout
    hold = max(core.sensors[odom].timeout_s, core.cfg.filter.gap_s)
    assert odom_timeout == silent_after(hold, s.period[odom], longest=s.longest[odom][0])
    assert odom_timeout >= held.timeout(odom, s)
    assert gyro_timeout == held.timeout(s.gyro_last[0], s)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.005, 2.0), st.floats(0.001, 2.0), st.integers(0, 6))
def test_timeouts_and_expiries_are_the_two_calls(odom_period, imu_period, n):
    core = _driven((odom_period, imu_period), n) if n else FusionCore(make_config())
    if n == 0:
        core.ingest(imu(1.0))  # a gyro rate, no odometry yet
    s, held = core.state, core.inputs
    timeouts = held.timeouts(s)
    assert held.timeouts_and_expiries(s) == (timeouts, held.expiries(s, timeouts))


def test_timeouts_are_zero_for_inputs_not_yet_held():
    core = FusionCore(make_config())
    core.ingest(imu(1.0))  # a gyro rate, no odometry yet
    s = core.state
    assert core.inputs.timeouts(s)[0] == 0.0
    assert core.inputs.timeouts(s)[1] == core.inputs.timeout(s.gyro_last[0], s)


@given(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0), st.floats(-10.0, 10.0), st.floats(0.0, 10.0))
def test_next_expiry_is_the_first_expiry_after_t_and_before_the_end(odom_e, gyro_e, t, span):
    end = t + span
    later = [e for e in (odom_e, gyro_e) if t < e]
    assert next_expiry((odom_e, gyro_e), t, end) == min([end, *later])
    assert next_expiry((-math.inf, -math.inf), t, end) == end


def test_pose_variances_are_the_published_covariance_diagonal():
    core = _driven((0.02, 0.01), 50)
    c = core.estimate().pose_covariance
    assert core.pose_variances() == [c[7 * i] for i in range(6)]


@given(st.tuples(*[st.floats(allow_nan=True, allow_infinity=True, width=64)] * 4)
       | st.tuples(*[st.floats(-1.05, 1.05)] * 4))
def test_near_unit_is_unit_quaternion_where_it_answers_and_covers_every_finite_refusal(q):
    """The IMU's one check of the usual message: a quaternion ``near_unit`` accepts is finite and
    normalised to the bit as ``unit_quaternion`` normalises it; one it declines is refused by
    ``unit_quaternion`` or is not finite (the core's NON_FINITE check says so first)."""
    from fusiond.core.sensors.checks import Rejected, finite, near_unit, unit_quaternion

    got = near_unit(q)
    if got is not None:
        assert finite(q)
        assert got == unit_quaternion(q)
    elif finite(q):
        try:
            unit_quaternion(q)
        except Rejected:
            pass
        else:
            raise AssertionError(f"near_unit declined {q}, which unit_quaternion accepts")


@given(st.tuples(*[st.floats(-1e3, 1e3)] * 9), st.tuples(*[st.floats(-1e3, 1e3)] * 9))
def test_the_published_twist_covariance_is_the_two_blocks_on_the_diagonal(linear, angular):
    import numpy as np

    from fusiond.core.fusion import _twist_covariance

    full = np.zeros((6, 6))
    full[0:3, 0:3] = np.reshape(linear, (3, 3))
    full[3:6, 3:6] = np.reshape(angular, (3, 3))
    assert _twist_covariance(linear, angular) == full.ravel().tolist()
