"""An absolute (magnetometer) yaw that can be wrong, beside a GPS.

The IMU's yaw is heading + offset: an estimated offset block (constant + random walk),
made observable by the GPS track, with navsat_transform's yaw_offset / magnetic_declination
applied first, and a gate on yaw jumps the gyro does not see.
"""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate


def _config(orientation: str, imu: str = "", gps: bool = True):
    return robot_config(gps="" if gps else None, imu=imu, orientation=orientation)


def _fuse(samples, w: World, cfg) -> tuple[float, FusionCore, list[float]]:
    """Horizontal RMS against the truth after 30 s; the core; stamps of gated yaw jumps."""
    truth = {round(t, 6): (x, y) for t, x, y, _ in w.truth}
    core = FusionCore(cfg)
    err, jumps = [], []
    for s in samples:
        step = core.ingest(s)
        jumps += [s.stamp - 1000.0 for r in step.records if r.channel == "yaw_jump"]
        if step.publish and s.stamp > 1030.0:
            t, x = core.pose()
            tx, ty = truth[round(t, 6)]
            err.append(math.hypot(x[0] - tx, x[1] - ty))
    return math.sqrt(sum(e * e for e in err) / len(err)), core, jumps


def test_magnetometer_yaw_with_an_offset_and_disturbances_is_no_worse_than_roll_pitch():
    """A magnetometer reading 0 facing north (offset pi/2 - 0.07 rad of mounting: 1.5 rad), a slow
    disturbance of 0.5 rad (period 20 s) and two steps switched on and off (0.6 rad for 10 s,
    -0.5 rad for 60 s); GPS 1.5 m at 1 Hz; the filter starts 2 rad off. Roll/pitch + gyro + GPS
    ignores the yaw and sets the bar. With the offset state and the jump gate the same data with
    the yaw fused must end within 10 % of it, learn the offset, and gate exactly the four step
    edges (a 0.5 rad jump against a 0.03 rad allowance; the sinusoid moves 0.003 rad per sample).
    Trusting the reading as heading (yaw_offset_sigma = 0) is what the issue measured: far worse."""
    w = World(duration=300.0, speed=1.0, gps_rate=1.0, gps_sigma=1.5, start=(0.0, 0.0, 2.0), gyro_bias=0.002,
              imu_yaw_offset=1.5, imu_yaw_disturbance=(0.5, 20.0),
              imu_yaw_steps=((100.0, 110.0, 0.6), (200.0, 260.0, -0.5)), seed=5)
    samples = simulate(w)
    bar, _, _ = _fuse(samples, w, _config("roll_pitch"))
    mag, core, jumps = _fuse(samples, w, _config("absolute"))
    assert mag <= 1.1 * bar, (mag, bar)
    assert float(core.state.ekf.x[core.layout.nominal["yaw_offset"]][0]) == pytest.approx(1.5, abs=0.05)
    assert [round(t) for t in jumps] == [100, 110, 200, 260]
    trusted, _, _ = _fuse(samples, w, _config("absolute", "yaw_offset_sigma = 0.0"))
    assert trusted > 2.0 * bar


@pytest.mark.parametrize("extra, expected", [
    ("", 0.2),
    ("yaw_offset = 1.5707963", 0.2 + math.pi / 2),  # an IMU reading 0 facing north
    ("yaw_offset = 1.5707963\nmagnetic_declination = 0.05", 0.25 + math.pi / 2),
    ("magnetic_declination = -0.1", 0.1),
])
def test_yaw_offset_and_magnetic_declination_follow_navsat_transform(extra, expected):
    """ENU yaw = reading + yaw_offset + magnetic_declination (navsat_transform's convention)."""
    core = FusionCore(_config("absolute", extra, gps=False))
    cov36 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    for k in range(20):
        t = 10.0 + 0.02 * k
        core.ingest(OdomSample("wheel", t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), cov36))
        core.ingest(ImuSample("imu", t + 0.001, rot.from_rpy(0.0, 0.0, 0.2), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                              (0.0,) * 3, (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)))
    assert rot.yaw(tuple(core.pose()[1][3:7].tolist())) == pytest.approx(rot.wrap(expected), abs=1e-3)
    assert not core.layout.has("yaw_offset")  # nothing absolute to estimate it against


def test_the_offset_state_exists_only_beside_an_absolute_sensor_and_no_tilt_or_delta_update_writes_it():
    assert not FusionCore(_config("roll_pitch")).layout.has("yaw_offset")
    assert not FusionCore(_config("absolute", "yaw_offset_sigma = 0.0")).layout.has("yaw_offset")
    core = FusionCore(_config("absolute"))
    e = core.layout.error["yaw_offset"]
    assert not core.tilt_mask[e].any() and not core.position_mask[e].any() and not core.delta_mask[e].any()


def test_the_doctor_says_what_the_yaw_jumps_were():
    """The four step edges of the world above, gated (every yaw_jump record is a reading the gate kept out):
    the channel's NIS is not judged (it is beyond the gate by construction) and the verdict counts them, a
    share of the IMU's readings far below JUMP_NOTE_SHARE: ok, a disturbance switching on now and then."""
    from fusiond.doctor.checks.yaw_jump import JUMP_NOTE_SHARE
    from fusiond.replay.run import run_samples

    from tests.support.verdicts import agree, one

    w = World(duration=300.0, speed=1.0, gps_rate=1.0, gps_sigma=1.5, start=(0.0, 0.0, 2.0), gyro_bias=0.002,
              imu_yaw_offset=1.5, imu_yaw_disturbance=(0.5, 20.0),
              imu_yaw_steps=((100.0, 110.0, 0.6), (200.0, 260.0, -0.5)), seed=5)
    result = run_samples(simulate(w), _config("absolute"))
    verdicts = result.verdicts()
    agree(result.doctor, verdicts)
    assert result.doctor.channel_summaries()["imu/yaw_jump"]["verdict"] == "not_judged"
    v = one(verdicts, "imu", "yaw_jump")
    assert v.level == "ok" and v.evidence["yaw_jumps"] == 4.0 and v.evidence["yaw_jump_share"] < JUMP_NOTE_SHARE, v
    assert "jumped against the gyro-carried heading" in v.message and "nis" not in v.message.lower(), v


def _heading_rms(samples, w: World, cfg) -> float:
    """Heading RMS against the truth after 30 s."""
    truth = {round(t, 6): yaw for t, _, _, yaw in w.truth}
    core = FusionCore(cfg)
    err = []
    for s in samples:
        if core.ingest(s).publish and s.stamp > 1030.0:
            t, x = core.pose()
            err.append(rot.wrap(rot.yaw(tuple(x[3:7].tolist())) - truth[round(t, 6)]))
    return math.sqrt(sum(e * e for e in err) / len(err))


def _kept_absolute(steps):
    """A magnetometer 0.35 rad off and disturbed by ``steps`` beside a 1.5 m GPS at 1 Hz: (world, samples,
    the advised yaw_offset), the verdict asserted to find the disturbance (beyond 2 WANDER_RAD against the
    gyro), the estimate not following it (within WANDER_RAD) and so to keep the yaw absolute."""
    from fusiond.doctor.heading import WANDER_RAD
    from fusiond.replay.run import run_samples

    w = World(duration=300.0, speed=1.0, gps_rate=1.0, gps_sigma=1.5, gyro_bias=0.002,
              imu_yaw_offset=0.35, imu_yaw_steps=steps, seed=5)
    samples = simulate(w)
    v = next(v for v in run_samples(samples, _config("absolute")).verdicts()
             if v.sensor == "imu" and v.channel == "orientation")
    assert v.evidence["imu_vs_gyro_wander_rad"] > 2 * WANDER_RAD, v  # the simulation has the trait
    assert v.evidence["estimate_vs_gyro_wander_rad"] <= WANDER_RAD, v
    assert v.level == "warn" and "keep the yaw absolute" in v.message and v.key == "sensors.imu.yaw_offset", v
    return w, samples, float(v.suggestion.split("=")[1])


def test_a_disturbed_magnetometer_the_filter_absorbs_is_kept_absolute_with_its_offset_corrected():
    """A skid-steer: a magnetometer 0.35 rad off, disturbed near steel by steps of +0.6 rad for 15 s and
    -0.9 rad for 18 s; GPS 1.5 m at 1 Hz. The IMU's yaw wanders against the gyro far beyond WANDER_RAD, yet
    the jump gate drops the steps' edges and the offset state takes the rest: the estimate's heading stays
    within WANDER_RAD of the gyro's shape, and the run is no worse than roll_pitch's (roll_pitch would
    make the run worse: 0.395 rad against 0.077, the GPS heading searched from travel again). So the verdict
    keeps the yaw absolute and names the offset (within 0.1 rad: the chords' standard error is ~0.02, the
    disturbances' remainder the rest); pasted, the heading is no worse (5 % allowed)."""
    w, samples, advised = _kept_absolute(((100.0, 115.0, 0.6), (200.0, 218.0, -0.9)))
    assert advised == pytest.approx(-0.35, abs=0.1)
    absolute = _heading_rms(samples, w, _config("absolute"))
    assert absolute <= 1.05 * _heading_rms(samples, w, _config("roll_pitch"))
    assert _heading_rms(samples, w, _config("absolute", f"yaw_offset = {advised}")) <= 1.05 * absolute


def test_a_magnetometer_disturbed_at_start_up_is_judged_once_the_gps_gives_the_heading():
    """The magnetometer (0.35 rad off) disturbed by +0.9 rad for the first 40 s, GPS 1.5 m at 1 Hz. Until
    travel has shown the GPS heading, the estimate can only follow the IMU's yaw, disturbance and all: judged
    over the whole run it "followed" it, and roll_pitch would be advised (pasted: 0.416 m, against 0.173
    with the offset's 0.125). Judged once the heading is known (attitude variance within HEADING_READY_SIGMA^2), it did
    not follow: the yaw stays absolute and its offset is named. The advised offset carries the start's
    disturbance, 0.9 x 40 s over the run's ~250 s of track segments (~0.15 rad): asserted within 0.2 of the
    truth; pasted, the heading is no worse than as configured (5 % allowed)."""
    w, samples, advised = _kept_absolute(((0.0, 40.0, 0.9),))
    assert advised == pytest.approx(-0.35, abs=0.2)
    absolute = _heading_rms(samples, w, _config("absolute"))
    pasted = _heading_rms(samples, w, _config("absolute", f"yaw_offset = {advised}"))
    assert pasted <= 1.05 * absolute
