"""The highway car as `fusiond init` and the README write its config: the IMU pitched in its mount, unstated.
With no fix for 20 s from 25 s in (``scripts/recording_variants.py``'s ``comma_outage20``) the twist climbs 7 m per
100 m; the GPS's vertical error state takes it (23 m when the fixes stop, short of the 24.5 m, 4.9 sigmas, that
would refute it), the climb goes on through the outage, and the height is then off by more than the altitude's
gate allows: the fixes' altitudes are gated out until they have agreed for 3 s, and the height is taken from them
again (``gps_altitude_reacquired``). With pitch_estimation held (false) the climb starts over, and the doctor's
problem on the mount says the altitude was gated (not "the altitude's NIS looks normal"); the altitude's own
verdict is explained by it and names extrinsic_rpy, not the gate. At the default ("auto") the lock-out refutes the
wander and the twist's pitch is learned from then on. As recorded, the wander state's height is refuted and the
pitch learned. Skipped without the recording."""

from __future__ import annotations

from fusiond.config import loads
from fusiond.replay.run import replay

from tests.support.recordings import HIGHWAY_CONFIG, needs, write_variant

pytestmark = needs("comma2k19_ex1", "the highway car")

CONFIG = HIGHWAY_CONFIG


HELD = CONFIG.replace('twist_frame = "body"', 'twist_frame = "body"\npitch_estimation = false')


def test_the_altitude_gated_by_an_unstated_mount_is_put_down_to_the_mount(tmp_path):
    bag = write_variant("comma_outage20", tmp_path / "comma_outage20")
    result = replay([bag], loads(HELD), progress=False)
    verdicts = result.verdicts()
    attitude = next(v for v in verdicts if v.sensor == "imu" and v.channel == "attitude")
    up = next(v for v in verdicts if v.sensor == "gps" and v.channel == "altitude")
    assert result.doctor.channels[("gps", "altitude")].rejected > 0  # the recording has the trait
    assert attitude.level == "problem" and "gated" in attitude.message and "looks normal" not in attitude.message
    assert up.key == "sensors.imu.extrinsic_rpy" and "explained by imu/attitude" in up.message, up
    # at the default the lock-out itself refutes the wander: the height is taken from the fixes and the pitch learned
    auto = replay([bag], loads(CONFIG), progress=False)
    gated = auto.doctor.channels[("gps", "altitude")].rejected  # the lock-out ends at the same fix either way
    assert gated == result.doctor.channels[("gps", "altitude")].rejected, gated
    assert result.core.twist_pitch is None
    assert auto.core.twist_pitch is not None and abs(auto.core.twist_pitch - 0.0747) < 3 * 0.008, auto.core.twist_pitch


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


def test_the_config_a_user_writes_learns_the_unstated_mount_once_the_altitude_refutes_its_wander():
    """The highway car as recorded with the README's config (pitch_estimation at its default, "auto"): the
    wander state takes the climb until it holds beyond 4.9 of its 5 m (27 s in), then the height is the car's
    and the twist's pitch is learned (the doctor's fit: 0.0747 +- 0.008 rad). At the end the published height
    is within metres of the fixes' altitude, where held (false) it is tens of metres off."""
    from structlog.testing import capture_logs

    import fusiond.logs
    from tests.support.recordings import DATA

    fusiond.logs.configure("warning")
    with capture_logs() as logs:
        auto = replay([DATA / "comma2k19_ex1"], loads(CONFIG), progress=False, doctor=False)
    held = replay([DATA / "comma2k19_ex1"], loads(HELD), progress=False, doctor=False)
    released = [e for e in logs if e["event"] == "height_refuted"]
    assert len(released) == 1 and abs(released[0]["wander_m"]) > 24.4, released
    assert abs(auto.core.twist_pitch - 0.0747) < 3 * 0.008, auto.core.twist_pitch
    assert held.core.twist_pitch is None

    def wander(result) -> float:
        """The altitude's wander state at the end: z + b is what the fixes measure, so b is how far the
        published height has left them."""
        layout = result.core.layout
        return abs(float(result.core.state.ekf.x[layout.nominal["gps_error"].start + 2]))

    assert wander(auto) < 5.0 and wander(held) > 20.0, (wander(auto), wander(held))
