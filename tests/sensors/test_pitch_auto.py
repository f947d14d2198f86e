"""pitch_estimation = "auto" (the default): the twist's pitch is held at the mount as configured until the GPS's
altitude wander state holds a height its model refutes (core/sensors/gps/model.py ``_refuted_height``), then
released. The world of tests/doctor/test_doctor_grade.py: level ground, loops at 5 m/s for 150 s, 5 Hz fixes of
0.5 m, the IMU pitched in its mount by 0.05 rad (unstated): the body-frame twist sinks 5 cm per metre."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusiond.logs
from fusiond.core.fusion import FusionCore
from fusiond.estimator import ErrorStateEKF, GpsErrorBlock, PoseBlock, StateLayout, TwistPitchBlock

from tests.support import sim_gps
from tests.support.configs import robot_config

MOUNT = 0.05
WORLD = dict(duration=150.0, speed=5.0, gps_rate=5.0, gps_sigma=0.5, arcs=((10.0, 150.0, 0.05),))


def _run(samples, odom: str = "", gps: str = "", after: float = 20.0) -> tuple[FusionCore, float]:
    """The core after the run, and the RMS of its published z ``after`` s on (the truth is 0)."""
    core = FusionCore(robot_config(gps=gps, odom=odom))
    zs = [core.pose()[1][2] for s in samples if core.ingest(s).publish and s.stamp > sim_gps.T0 + after]
    return core, math.sqrt(sum(z * z for z in zs) / len(zs))


def test_an_unstated_mount_pitch_is_released_and_learned_where_held_it_sinks_the_height():
    from structlog.testing import capture_logs

    fusiond.logs.configure("warning")
    samples = sim_gps.simulate(sim_gps.World(**WORLD, imu_mount_pitch=MOUNT))
    with capture_logs() as logs:
        auto, _ = _run(samples)
    released = [e for e in logs if e["event"] == "height_refuted"]
    assert len(released) == 1, released  # once
    # beyond the model's chi-square(1) bound at 1e-6 (4.89 of the wander's 5 m): 25 m of sinking at 5 cm a metre
    # takes ~100 s at 5 m/s; the last 30 s are after it
    assert abs(released[0]["wander_m"]) > 4.89 * 5.0 and released[0]["stamp"] < sim_gps.T0 + 120.0, released
    _, auto_rms = _run(samples, after=120.0)
    never, never_rms = _run(samples, odom="pitch_estimation = false", after=120.0)
    assert never.twist_pitch is None  # not in the state
    assert auto.twist_pitch is not None and abs(abs(auto.twist_pitch) - MOUNT) < 0.01, auto.twist_pitch
    # held (false), the wander state takes the sinking body for receiver wander: metres off the level ground
    assert never_rms > 5.0 and auto_rms < 1.0, (auto_rms, never_rms)


def test_a_level_mount_is_never_released_and_changes_nothing():
    """No unmodelled climb: the held pitch stays out of every estimate (no variance: the same poses as with
    pitch_estimation = false, to the bit) and the summary shows no twist_pitch."""
    samples = sim_gps.simulate(sim_gps.World(**WORLD))
    auto, _ = _run(samples)
    never, _ = _run(samples, odom="pitch_estimation = false")
    assert auto.layout.has("twist_pitch") and not never.layout.has("twist_pitch")
    assert auto.twist_pitch is None
    np.testing.assert_array_equal(auto.pose()[1], never.pose()[1])


@pytest.mark.parametrize("gps, held", [("", True), ("vertical_error_sigma = 0.0", False)])
def test_auto_holds_the_pitch_only_beside_an_altitude_wander_state(gps, held):
    """Without a wander state nothing would release it: it is not in the state at all."""
    assert FusionCore(robot_config(gps=gps)).layout.has("twist_pitch") is held


def test_reattribute_keeps_what_the_fixes_measure_and_the_covariance_psd():
    layout = StateLayout([PoseBlock(1.0, 0.1), TwistPitchBlock(0.0, 0.0, release_sigma=0.1),
                          GpsErrorBlock(300.0, (0.0, 0.0, 5.0))])
    rng = np.random.default_rng(3)
    A = rng.normal(size=(layout.error_dim, layout.error_dim))
    P = A @ A.T
    pitch = layout.error["twist_pitch"].start
    P[pitch, :] = P[:, pitch] = 0.0  # held
    ekf = ErrorStateEKF(layout, P=P)
    b_n, b_e = layout.nominal["gps_error"].start + 2, layout.error["gps_error"].start + 2
    ekf.x[2], ekf.x[b_n] = 1.5, 30.0
    h = np.zeros(layout.error_dim)
    h[2] = h[b_e] = 1.0  # the altitude a fix measures: z + b
    before_var = h @ ekf.P @ h
    ekf.reattribute((b_n, b_e), (2, 2), 25.0, ([pitch], np.array([[0.01]])))
    assert ekf.x[2] == 31.5 and ekf.x[b_n] == 0.0
    assert ekf.P[b_e, b_e] == 25.0 and not ekf.P[b_e, :b_e].any() and ekf.P[pitch, pitch] == 0.01
    assert np.linalg.eigvalsh(ekf.P).min() > -1e-9
    # z' + b' = z + b; var(z') = var(z + b)
    assert ekf.P[2, 2] == pytest.approx(before_var)
