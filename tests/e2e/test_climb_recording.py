"""The highway car with no fix for 20 s from 25 s in (``scripts/recording_variants.py``'s ``comma_outage20``), as
`fusiond init` writes its config: the IMU pitched in its mount, unstated, and no pitch_estimation. The twist climbs
7 m per 100 m; the GPS's vertical error state takes it, through the outage too, until the height is off by more
than the altitude's gate allows, and the fixes' altitudes are then gated out. The doctor's problem on the mount
says so (not "the altitude's NIS looks normal"), and the altitude's own verdict is explained by it and names
extrinsic_rpy, not the gate. Skipped without the recording."""

from __future__ import annotations

from fusiond.config import loads
from fusiond.replay.run import replay

from tests.support.recordings import HIGHWAY_CONFIG, needs, write_variant

pytestmark = needs("comma2k19_ex1", "the highway car")

CONFIG = HIGHWAY_CONFIG


def test_the_altitude_gated_by_an_unstated_mount_is_put_down_to_the_mount(tmp_path):
    bag = write_variant("comma_outage20", tmp_path / "comma_outage20")
    result = replay([bag], loads(CONFIG), progress=False)
    verdicts = result.verdicts()
    attitude = next(v for v in verdicts if v.sensor == "imu" and v.channel == "attitude")
    up = next(v for v in verdicts if v.sensor == "gps" and v.channel == "altitude")
    assert result.doctor.channels[("gps", "altitude")].rejected > 0  # the recording has the trait
    assert attitude.level == "problem" and "gated" in attitude.message and "looks normal" not in attitude.message
    assert up.key == "sensors.imu.extrinsic_rpy" and "explained by imu/attitude" in up.message, up


STATED_MOUNT = CONFIG.replace('angular_velocity = true', 'angular_velocity = true\nextrinsic_rpy = [0.0, 0.0741, 0.0]')


def test_the_altitude_nis_low_of_a_slow_vertical_error_over_a_short_run_is_the_models_not_a_warning(tmp_path):
    """The highway car as recorded, its mount stated: 60 s against the vertical error state's 300 s. Every
    fix's predicted spread carries the whole modelled wander (5 m) while the run shows a slice of it, so the
    altitude's NIS is far below 1 per dof. The verdict says that NIS and why it is expected, at level ok with
    nothing to paste: no noise of the fixes mends it."""
    from fusiond.replay.run import replay as replay_bags
    from tests.support.recordings import DATA

    result = replay_bags([DATA / "comma2k19_ex1"], loads(STATED_MOUNT), progress=False)
    up = next(v for v in result.verdicts() if v.sensor == "gps" and v.channel == "altitude")
    assert result.doctor.channels[("gps", "altitude")].verdict() == "nis_low"  # the trait
    assert up.level == "ok" and up.message.startswith("NIS low") and "expects" in up.message, up
    assert not up.key and not up.suggestion, up
