"""The IMU mounting-pitch verdict (doctor/checks/lean.py) against the simulation's mount (tests/support/sim_gps.py).

The world: level ground, a robot driving loops at 5 m/s for 150 s, 5 Hz fixes of 0.5 m white noise on
every axis, its IMU pitched in its mount by 0.05 rad with ``extrinsic_rpy`` left at 0: the filter's
body pitch is the IMU's, so the body-frame twist sinks 5 cm per metre driven and the GPS's vertical
error state takes the difference for receiver wander. The fit's standard error is what it reports
(~0.006 rad here: the default 5 m vertical wander over 750 m of chords); its estimate is held to the
simulated mount within 3 of them.
"""

from __future__ import annotations

import math

from fusiond.doctor.checks.lean import WANDER_SIGMAS, GradeFit, grade_fit, grade_verdict
from fusiond.core.fusion import FusionCore
from fusiond.replay.run import run_samples

from tests.support import sim_gps
from tests.support.configs import robot_config

MOUNT = 0.05
WORLD = dict(duration=150.0, speed=5.0, gps_rate=5.0, gps_sigma=0.5, arcs=((10.0, 150.0, 0.05),))


HELD = "pitch_estimation = false"  # the twist's pitch never estimated: the climb stays the wander state's


def attitude_of(samples, imu: str = "", gps: str = "", odom: str = HELD):
    verdicts = run_samples(samples, robot_config(gps=gps, imu=imu, odom=odom)).verdicts()
    return next((v for v in verdicts if v.sensor == "imu" and v.channel == "attitude"), None)


def up_rms(samples, imu: str = "", odom: str = HELD) -> float:
    """RMS of the published z (the ground is level: the truth is 0) after the first 20 s."""
    core = FusionCore(robot_config(gps="", imu=imu, odom=odom))
    zs = [core.pose()[1][2] for s in samples if core.ingest(s).publish and s.stamp > sim_gps.T0 + 20.0]
    return math.sqrt(sum(z * z for z in zs) / len(zs))


def test_a_pitched_imu_is_found_from_the_gps_climb_and_pasting_it_keeps_z_on_the_ground():
    samples = sim_gps.simulate(sim_gps.World(**WORLD, imu_mount_pitch=MOUNT))
    v = attitude_of(samples)
    # 5 cm a metre over ~750 m of chords is ~37 m of climb, beyond 3 x the default vertical error state's 5 m:
    # no receiver wander, and the published height leaves the fixes by about that: a problem
    assert v is not None and v.level == "problem" and v.key == "sensors.imu.extrinsic_rpy", v
    assert "GPS altitude" in v.message and "pitch_estimation = true" in v.message
    # by default ("auto") the wander state's refuted height releases the filter's own pitch, which learns the
    # mount: a warning saying so, the same line to paste
    auto = attitude_of(samples, odom="")
    assert auto.level == "warn" and "twist_pitch state learns" in auto.message, auto
    assert auto.key == v.key and auto.suggestion.split("[")[0] == v.suggestion.split("[")[0], auto
    climb = v.evidence["unmodelled_climb_m"]
    assert abs(climb - abs(v.evidence["mount_pitch_error_rad"]) * v.evidence["grade_distance_m"]) < 1e-6, v.evidence
    delta, se = v.evidence["mount_pitch_error_rad"], v.evidence["mount_pitch_error_se"]
    assert abs(delta - MOUNT) < 3 * se, v.evidence
    pasted = v.suggestion
    pitch = float(pasted.split("[")[1].split(",")[1])
    assert abs(pitch - MOUNT) < 3 * se, pasted
    # pasted, z stays on the level ground (the unstated mount let it sink 5 cm per metre, the vertical
    # error state absorbing what the fixes said), and the verdict then reads ok
    before, after = up_rms(samples), up_rms(samples, imu=pasted)
    assert after < 0.5 * before, (before, after)
    # unstated, the filter's own twist_pitch state (pitch_estimation) learns it from the same climb
    assert up_rms(samples, odom="pitch_estimation = true") < 0.5 * before
    cfg = robot_config(gps="", imu=pasted)
    fit = grade_fit(run_samples(samples, cfg).doctor.collector.finish(), cfg)
    assert fit is not None and not fit.named and abs(fit.delta) < 3 * fit.se, fit


def test_an_altitude_the_gate_rejected_for_seconds_does_not_hide_the_pitched_mount():
    """The same pitched IMU, the receiver's altitude 30 m off for 5 s (a switch of its height reference and
    back): the gate rejects those fixes, so no chord may end on them. Ending there, the chords took 30 m of
    climb the filter never believed, the fit's band widened past any verdict and the mount went unnamed.
    Asserted: the problem is named as without the excursion, its pitch within 3 of its standard errors."""
    samples = sim_gps.simulate(sim_gps.World(**WORLD, imu_mount_pitch=MOUNT, gps_alt_jump=(60.0, 65.0, 30.0)))
    v = attitude_of(samples)
    assert v is not None and v.level == "problem" and v.key == "sensors.imu.extrinsic_rpy", v
    delta, se = v.evidence["mount_pitch_error_rad"], v.evidence["mount_pitch_error_se"]
    assert abs(delta - MOUNT) < 3 * se, v.evidence

def test_a_level_imu_is_not_named_and_without_gps_altitude_the_grade_says_nothing():
    samples = sim_gps.simulate(sim_gps.World(**WORLD))
    cfg = robot_config(gps="")
    result = run_samples(samples, cfg)
    fit = grade_fit(result.doctor.collector.finish(), cfg)
    assert fit is not None and not fit.named and abs(fit.delta) < 3 * fit.se, fit
    v = next((v for v in result.verdicts() if v.sensor == "imu" and v.channel == "attitude"), None)
    assert v is None or v.level == "ok", v
    # the altitude left out of the fusion: no grade to compare with, and the lean check (level ground
    # assumed) is the one that speaks on a pitched IMU
    pitched = sim_gps.simulate(sim_gps.World(**WORLD, imu_mount_pitch=MOUNT))
    lean = attitude_of(pitched, gps="position_noise = [0.5, 0.5, 1e6]")
    assert lean is not None and "mount_pitch_error_rad" not in lean.evidence and "lean_pitch_rad" in lean.evidence, lean


def test_the_climb_is_a_problem_only_beyond_what_the_vertical_error_state_allows():
    """The level of a named mount pitch: a problem when the climb over the drive exceeds WANDER_SIGMAS of the
    vertical error state's sigma (the state takes it, the height leaves the fixes), else a warning; a warning
    too when the filter learns the pitch itself, or when there is no such state (the fixes then hold z)."""
    imu = robot_config(gps="").sensor("imu")
    fit = lambda sigma: GradeFit(0.05, 0.004, 0.004, 20, 750.0, 1, sigma)  # 37.5 m of climb  # noqa: E731
    assert grade_verdict(fit(5.0), imu, None).level == "problem"
    assert grade_verdict(fit(37.5 / WANDER_SIGMAS - 0.1), imu, None).level == "problem"
    assert grade_verdict(fit(37.5 / WANDER_SIGMAS + 0.1), imu, None).level == "warn"
    assert grade_verdict(fit(0.0), imu, None).level == "warn"
    learned = grade_verdict(fit(5.0), imu, None, learned=True)
    assert learned.level == "warn" and "twist_pitch state learns" in learned.message


def test_the_climb_verdict_quotes_what_the_altitude_channel_shows_and_explains_its_gated_fixes():
    """The problem's message says what the altitude's own channel shows of the climb: "looks normal" only where its
    NIS is ok, the share gated where the fixes left the gate (a highway car starting at speed: 38 %). And a GPS
    altitude verdict that is not ok beside that problem is explained by it and names its key (extrinsic_rpy), not
    the gate or the noise (pasting mahalanobis_threshold = 10 made the altitude read ok, its error still 38 m: on
    the recording, tests/e2e/test_climb_recording.py)."""
    from fusiond.core.diagnostics import DiagnosticsRecord
    from fusiond.doctor.nis import ChannelStats

    def altitude(rejected: int, nis: float = 1.0) -> ChannelStats:
        ch = ChannelStats(["up"])
        ch.extend([DiagnosticsRecord(100.0 + i, "gps", ["up"], [1.0], [1.0 / nis], nis, 1, i < rejected,
                                     channel="altitude") for i in range(200)])
        return ch

    imu = robot_config(gps="").sensor("imu")
    fit = GradeFit(0.05, 0.004, 0.004, 20, 750.0, 1, 5.0)  # 37.5 m of climb
    assert "looks normal" in grade_verdict(fit, imu, None, altitude=altitude(0)).message
    gated = grade_verdict(fit, imu, None, altitude=altitude(76, 20.0)).message
    assert "38% gated" in gated and "looks normal" not in gated, gated
    assert "reads high" in grade_verdict(fit, imu, None, altitude=altitude(0, 20.0)).message

    # the check reads the run's own altitude channel: here ok (the state absorbed the climb), and said so
    samples = sim_gps.simulate(sim_gps.World(**WORLD, imu_mount_pitch=MOUNT))
    verdicts = run_samples(samples, robot_config(gps="", odom=HELD)).verdicts()
    up = next(v for v in verdicts if v.sensor == "gps" and v.channel == "altitude")
    attitude = next(v for v in verdicts if v.sensor == "imu" and v.channel == "attitude")
    assert up.level == "ok" and attitude.level == "problem" and "looks normal" in attitude.message, attitude


def test_the_wander_the_grade_is_judged_by_is_the_state_the_gps_puts_in_the_filter():
    """The three-axis error state (error_tau_s) is the filter's when configured, whatever vertical_error_sigma says
    (``GpsKind.state_blocks``); else the vertical one; with neither, a wander is only assumed, and no state holds
    a climb (``GradeFit.state_sigma_m`` 0)."""
    from fusiond.core.layout import state_layout
    from fusiond.doctor.checks.lean import _vertical_noise
    from fusiond.doctor.series import Series

    for gps, expect in (("", (5.0, 300.0, True)),
                        ("error_tau_s = 60.0\nerror_sigma = [1.0, 1.0, 2.0]", (2.0, 60.0, True)),
                        ("vertical_error_sigma = 0.0", (None, None, False))):
        cfg = robot_config(gps=gps)
        _, sigma_m, tau, state = _vertical_noise(Series(), cfg.sensor("gps"))
        assert state == expect[2] == state_layout(cfg).has("gps_error"), gps
        if state:
            assert (sigma_m, tau) == expect[:2], gps
