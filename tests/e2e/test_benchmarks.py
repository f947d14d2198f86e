"""pytest-benchmark timings of the hot paths (`pytest --benchmark-enable tests/e2e/test_benchmarks.py`).

In the normal suite (benchmarks disabled) each runs once, as a smoke test of the
benchmarked code; the numbers are read from the benchmark table, never asserted.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock, StateLayout, predict
from fusiond.estimator import observations as obs
from fusiond.core.sensors import encode_sample, make_decoder

from tests.support.sim import SimConfig, simulate
from tests.support.core_samples import make_config


@pytest.fixture(scope="module")
def stream():
    return simulate(SimConfig(duration=5.0, standstill=1.0))


def test_bench_predict_and_roll_pitch_update(benchmark):
    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    ekf = ErrorStateEKF(layout)
    u = MotionInput()
    u.linear, u.angular = (0.5, 0.0, 0.0), (0.01, -0.02, 0.2)
    u.linear_cov = u.angular_cov = (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4)
    u.linear_period = u.angular_period = 0.01
    u.from_gyro = True
    noise = layout.noise_density(np.full(6, 4e-6))
    mask = np.ones(layout.error_dim, dtype=bool)
    mask[[0, 1, 2, 5, 8]] = False

    def step():
        x, F, Q = predict(layout, ekf.x, u, 0.01, noise)
        ekf.propagate(x, F, Q)
        y, H, R = obs.orientation(layout, ekf.x, (0.001, -0.002, 0.0), (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6), (0, 1))
        return ekf.update(y, H, R, mask=mask)

    res = benchmark(step)
    assert not res.rejected and np.isfinite(ekf.P).all()


def test_bench_core_ingest_stream(benchmark, stream):
    def run():
        core = FusionCore(make_config())
        for s in stream:
            core.ingest(s)
        return core

    core = benchmark(run)
    assert sum(st.applied for st in core.stats) == len(stream)


@pytest.mark.parametrize("kind", ["odom", "imu"])
def test_bench_cdr_decode(benchmark, stream, kind):
    sample = next(s for s in stream if (s.sensor == "wheel") == (kind == "odom"))
    payload = encode_sample(sample, "ros2-cdr") if kind == "odom" else encode_sample(sample, "ros2-cdr")
    decode = make_decoder(kind, "ros2-cdr", sample.sensor)
    out = benchmark(decode, payload)
    assert out.stamp == pytest.approx(sample.stamp, abs=1e-9)
