"""An IMU configured to give its orientation (roll_pitch) whose driver states every sample's orientation as not
measured (1e6 on the diagonal, beyond orientation_max_sigma): nothing of it is fused, and the doctor says so,
naming orientation_noise. Stated honestly, or stated by the config, nothing is said."""

from __future__ import annotations

import msgspec

from fusiond.core.sensors import ImuSample

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import one, verdicts_of

UNKNOWN = (1e6, 0.0, 0.0, 0.0, 1e6, 0.0, 0.0, 0.0, 1e6)


def _stating_unknown(samples):
    return [msgspec.structs.replace(s, orientation_covariance=UNKNOWN) if type(s) is ImuSample else s for s in samples]


def test_an_orientation_the_driver_calls_unknown_is_said_to_be_unfused():
    samples = simulate(SimConfig(duration=20.0, standstill=2.0))
    v = one(verdicts_of(make_config(), _stating_unknown(samples)), "imu", "orientation")
    assert v.level == "warn" and v.key == "sensors.imu.orientation_noise" and "none of its" in v.message, v
    honest = one(verdicts_of(make_config(), samples), "imu", "orientation")
    assert honest.level == "ok" and "none of its" not in honest.message, honest
    stated = verdicts_of(make_config(extra_imu="orientation_noise = [0.002, 0.002, 1.0]"), _stating_unknown(samples))
    assert not [v for v in stated if "none of its" in v.message], stated


def test_nothing_is_said_of_the_orientation_of_samples_never_fused_or_of_a_planar_filter():
    """Every IMU sample stamped 0 (a driver that never stamps): all dropped, which the input verdict names; the
    orientation check spoke of covariances that were never read. Under two_d_mode roll and pitch are held,
    whatever the messages state: not the driver's doing either."""
    samples = simulate(SimConfig(duration=20.0, standstill=2.0))
    unstamped = [msgspec.structs.replace(s, stamp=0.0) if type(s) is ImuSample else s for s in samples]
    verdicts = verdicts_of(make_config(), _stating_unknown(unstamped))
    assert not [v for v in verdicts if "none of its" in v.message], verdicts
    # nor of a gyro bias never learned for want of a standstill: the run had one, its samples never reached the filter
    assert not [v for v in verdicts if v.channel == "gyro_bias" and v.level != "ok"], verdicts
    assert any(v.sensor == "imu" and "invalid_stamp" in v.message for v in verdicts), verdicts
    planar = verdicts_of(make_config(extra_filter="two_d_mode = true"), _stating_unknown(samples))
    assert not [v for v in planar if "none of its" in v.message], planar
