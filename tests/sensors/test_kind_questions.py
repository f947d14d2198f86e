"""What the doctor and the tuner ask a sensor's kind: answered by the kind's own package, so that no
module outside core/sensors/ reads a kind's config strings or tests its config class."""

from __future__ import annotations

import pytest

from fusiond.config import ImuSensor


@pytest.mark.parametrize("orientation, fused, yaw, absolute, relative, tilt_only, rows", [
    ("absolute", True, True, True, False, False, (0, 1, 2)),
    ("relative", True, True, False, True, False, (0, 1, 2)),
    ("roll_pitch", True, False, False, False, True, (0, 1)),
    ("off", False, False, False, False, False, ()),
])
def test_the_imu_table_names_what_its_orientation_mode_fuses(orientation, fused, yaw, absolute, relative, tilt_only,
                                                             rows):
    imu = ImuSensor(name="imu", key="imu", orientation=orientation)
    assert (imu.fuses_orientation, imu.fuses_yaw, imu.absolute_yaw, imu.relative_yaw, imu.roll_pitch_only,
            imu.orientation_rows) == (fused, yaw, absolute, relative, tilt_only, rows)
    # roll and pitch come from the IMU in every mode while gravity gives them; "off" without it gives none
    assert imu.tilt_from_imu
    assert ImuSensor(name="imu", key="imu", orientation=orientation, tilt_from_gravity=False).tilt_from_imu == fused


TOML = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"

[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
orientation = "{orientation}"
angular_velocity = {gyro}

[[sensors]]
name = "fix"
kind = "gps"
key = "fix"

[[sensors]]
name = "vo"
kind = "pose"
key = "vo"
differential = true
"""


@pytest.mark.parametrize("orientation, gyro", [("roll_pitch", "true"), ("absolute", "false"), ("off", "true")])
def test_each_kind_answers_the_doctors_questions_about_it(orientation, gyro):
    from fusiond.config import loads
    from fusiond.core.sensors import kind_of

    cfg = loads(TOML.format(orientation=orientation, gyro=gyro))
    answers = {s.name: (kind_of(s).drives_prediction, kind_of(s).inertial, kind_of(s).geodetic,
                        kind_of(s).measures_position, kind_of(s).heading_reference(s), kind_of(s).fuses_gyro(s))
               for s in cfg.sensors}
    assert answers == {
        "wheel": (True, False, False, False, False, False),
        "imu": (False, True, False, False, orientation == "absolute", gyro == "true"),
        "fix": (False, False, True, True, True, False),
        "vo": (False, False, False, True, True, False),  # a differential pose's deltas reference heading too
    }


def test_a_kind_that_says_nothing_is_no_reference_of_any_kind():
    from tests.support.altimeter import AltimeterKind, AltimeterSensor

    kind, cfg = AltimeterKind(), AltimeterSensor(name="sonar", key="range")
    assert not (kind.inertial or kind.geodetic or kind.measures_position or kind.drives_prediction)
    assert not kind.heading_reference(cfg) and not kind.fuses_gyro(cfg)


def test_tune_fits_what_each_kind_declares_and_nothing_of_a_kind_that_declares_nothing():
    from fusiond.config import loads
    from fusiond.core.sensors import kind_of, register, unregister
    from fusiond.core.sensors.tunable import Param
    from fusiond.tune.params import tunable_params
    from tests.support.altimeter import AltimeterKind

    toml = '[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n\n' \
           '[[sensors]]\nname = "sonar"\nkind = "altimeter"\nkey = "range"\n'
    register(AltimeterKind())
    try:
        cfg = loads(toml)
        names = [p.name for p in tunable_params(cfg)]
        assert [n for n in names if n.startswith("sonar.")] == []  # the default: nothing to tune
        assert names[:2] == ["wheel.twist_noise.linear", "wheel.twist_noise.angular"]
        assert kind_of(cfg.sensors[0]).tunables(cfg.sensors[0], ()) == tunable_params(cfg)[:2]

        class TunedAltimeter(AltimeterKind):
            def tunables(self, cfg, samples):
                return [Param(f"{cfg.name}.range_sigma", cfg.name, "range_sigma", None, cfg.range_sigma, unit="m")]

        register(TunedAltimeter())
        assert "sonar.range_sigma" in [p.name for p in tunable_params(loads(toml))]
    finally:
        unregister("altimeter")
