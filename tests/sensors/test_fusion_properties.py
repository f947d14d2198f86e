"""Property tests: whatever the sensors send, the core neither raises nor goes non-finite."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.core_samples import make_config

wild = st.one_of(
    st.floats(-10.0, 10.0),
    st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300]),
)
variance = st.one_of(st.floats(0.0, 1.0), st.sampled_from([0.0, -1.0, 1e6, 1e300, math.nan, math.inf]))
stamp = st.one_of(
    st.floats(99.0, 101.0),
    st.sampled_from([0.0, -5.0, math.nan, math.inf, 1e12, 100.0, 100.0]),
)


@st.composite
def odom_samples(draw):
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = draw(variance)
    return OdomSample("wheel", draw(stamp), (draw(wild), draw(wild), draw(wild)), (draw(wild), draw(wild), draw(wild)),
                      tuple(cov))


@st.composite
def imu_samples(draw):
    q = (draw(wild), draw(wild), draw(wild), draw(wild))
    if draw(st.booleans()):
        n = math.sqrt(sum(c * c for c in q)) if all(math.isfinite(c) for c in q) else 0.0
        q = tuple(c / n for c in q) if 0 < n < 1e100 else (0.0, 0.0, 0.0, 1.0)
    ocov = (draw(variance), 0.0, 0.0, 0.0, draw(variance), 0.0, 0.0, 0.0, draw(variance))
    if draw(st.integers(0, 9)) == 0:
        ocov = (-1.0,) + ocov[1:]  # ROS: "no orientation"
    gcov = (draw(variance), 0.0, 0.0, 0.0, draw(variance), 0.0, 0.0, 0.0, draw(variance))
    return ImuSample("imu", draw(stamp), q, ocov, (draw(wild), draw(wild), draw(wild)), gcov)


def _check(core: FusionCore) -> None:
    if not core.initialised:
        return
    _, x = core.pose()
    assert np.isfinite(x).all()
    assert abs(float(x[3:7] @ x[3:7]) - 1.0) < 1e-9
    P = core.state.ekf.P
    assert np.isfinite(P).all()
    assert np.allclose(P, P.T, atol=1e-12 * max(1.0, np.abs(P).max()))
    assert np.linalg.eigvalsh(P).min() > -1e-9 * max(1.0, np.abs(P).max())
    est = core.estimate()
    assert all(math.isfinite(v) for v in (*est.position, *est.orientation, *est.pose_covariance))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(samples=st.lists(st.one_of(odom_samples(), imu_samples()), min_size=1, max_size=60),
       mode=st.sampled_from(["absolute", "relative", "roll_pitch", "off"]), gyro=st.booleans())
def test_arbitrary_input_never_raises_or_goes_non_finite(samples, mode, gyro):
    core = FusionCore(make_config(orientation=mode, gyro=gyro or mode == "off",
                                  extra_imu="mahalanobis_threshold = 6.0"))
    for s in samples:
        step = core.ingest(s)
        assert step.accepted or step.reason
        for r in step.records:
            assert len(r.innovation) == len(r.innovation_var) == len(r.components) == r.dof
        _check(core)
    received = sum(st.received for st in core.stats)
    # samples held for an unconfirmed time jump are neither applied nor dropped yet
    accounted = sum(st.applied + st.dropped_total for st in core.stats) + sum(core.held())
    assert received == accounted == len(samples)  # nothing lost silently


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), bad_every=st.integers(2, 6))
def test_valid_samples_mixed_with_garbage_still_track(seed, bad_every):
    """Valid samples keep being fused however much garbage arrives between them."""
    rng = np.random.default_rng(seed)
    clean, mixed = FusionCore(make_config()), FusionCore(make_config())
    garbage = [
        OdomSample("wheel", math.nan, (1.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 36),
        OdomSample("wheel", 1e12, (1.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 36),
        ImuSample("imu", 0.0, (0.0, 0.0, 0.0, 1.0), (1e-4,) * 9, (0.0,) * 3, (1e-6,) * 9),
        ImuSample("imu", 1.0, (0.0, 0.0, 0.0, 0.0), (1e-4,) * 9, (0.0,) * 3, (1e-6,) * 9),
        OdomSample("wheel", 1.0, (math.inf, 0.0, 0.0), (0.0,) * 3, (0.0,) * 36),
    ]
    for k in range(200):
        t = 10.0 + 0.01 * k
        cov = [0.0] * 36
        for i in range(6):
            cov[7 * i] = 1e-4
        good = [OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.1), tuple(cov)),
                ImuSample("imu", t + 0.002, (0.0, 0.0, 0.0, 1.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                          (0.0, 0.0, 0.1), (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6))]
        for g in good:
            clean.ingest(g)
            assert mixed.ingest(g).accepted
            if k % bad_every == 0:
                mixed.ingest(garbage[int(rng.integers(len(garbage)))])
    assert clean.pose()[1].tolist() == mixed.pose()[1].tolist()
    dropped = {r: n for st in mixed.stats for r, n in st.dropped.items()}
    assert dropped and set(dropped) <= {"invalid_stamp", "future_stamp", "zero_quaternion", "non_finite",
                                        "too_old", "stale_stamp"}
