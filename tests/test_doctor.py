"""The tuning doctor on simulated robots with a known fault."""

from __future__ import annotations

from fusiond.core.doctor import Doctor
from fusiond.core.fusion import FusionCore
from fusiond.estimator.rotation import to_rpy
from fusiond.samples import OdomSample

from .sim import SimConfig, simulate
from .test_fusion_core import make_config


def run_doctor(cfg, samples):
    core, doctor = FusionCore(cfg), Doctor(cfg)
    for s in samples:
        step = core.ingest(s)
        if isinstance(s, OdomSample):
            doctor.add_twist(s.linear, s.angular)
        for r in step.records:
            doctor.add(r)
        if step.publish:
            x = core.pose()[1].tolist()
            doctor.add_attitude(*to_rpy(tuple(x[3:7]))[0:2])
    stats = {s.name: {"received": st.received, "dropped": st.dropped} for s, st in zip(core.sensors, core.stats)}
    return doctor.verdicts(stats)


def test_disturbed_absolute_yaw_is_flagged_and_roll_pitch_gyro_suggested():
    samples = simulate(SimConfig(duration=30.0, imu_yaw_wander=0.3, standstill=2.0))
    verdicts = run_doctor(make_config(orientation="absolute", gyro=True), samples)
    ori = [v for v in verdicts if v.channel == "orientation" and v.level == "problem"]
    assert ori and ori[0].key == "sensors[1].orientation"
    assert "roll_pitch" in ori[0].message and "angular_velocity = true" in ori[0].message

    recommended = run_doctor(make_config(orientation="roll_pitch", gyro=True), samples)
    assert all(v.level == "ok" for v in recommended if v.channel == "orientation"), recommended


def test_understated_orientation_noise_is_flagged_with_a_measured_suggestion():
    samples = simulate(SimConfig(duration=20.0, orientation_sigma=0.02))
    verdicts = run_doctor(make_config(orientation="roll_pitch", gyro=True,
                                      extra_imu="orientation_noise = [0.002, 0.002, 0.002]"), samples)
    v = next(v for v in verdicts if v.channel == "orientation")
    assert v.level == "problem" and v.key == "sensors[1].orientation_noise"


def test_mounting_offset_is_reported_against_extrinsic_rpy():
    samples = simulate(SimConfig(duration=20.0))
    # the config claims a 3 degree roll mount the IMU does not have
    verdicts = run_doctor(make_config(orientation="roll_pitch", gyro=True, extra_imu="extrinsic_rpy = [0.05, 0.0, 0.0]"),
                          samples)
    assert any(v.key == "sensors[1].extrinsic_rpy" for v in verdicts), verdicts


def test_skid_steer_wheels_are_reported_as_slip():
    samples = simulate(SimConfig(duration=30.0, wheel_yaw_scale=2.3))
    verdicts = run_doctor(make_config(orientation="roll_pitch", gyro=True, extra_odom="slip_threshold = 0.1"), samples)
    assert any(v.channel == "yaw_rate" and v.level == "warn" for v in verdicts)


def test_world_twist_setting_on_a_body_twist_is_a_problem():
    samples = simulate(SimConfig(duration=20.0))
    verdicts = run_doctor(make_config(extra_odom='twist_frame = "world"'), samples)
    assert any(v.key == "sensors[0].twist_frame" and v.level == "problem" for v in verdicts)
