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


def test_an_installed_package_adds_a_kind_through_its_entry_point(tmp_path):
    """A third party's package names its descriptor under the ``fusiond.sensor_kinds`` entry point group:
    a config naming its tag loads with nothing in fusiond touched (here the toy altimeter, declared by a
    distribution's metadata on sys.path), and a run naming only built-in kinds never looks."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    dist = tmp_path / "site" / "fusiond_altimeter-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: fusiond-altimeter\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[fusiond.sensor_kinds]\naltimeter = tests.support.altimeter:AltimeterKind\n"
                                           "broken = tests.support.no_such_module:Kind\n")
    code = ("import json, sys, warnings\n"
            "warnings.simplefilter('ignore')\n"
            "from fusiond.config import loads\n"
            "from fusiond.core.sensors import KINDS\n"
            "plain = loads('[[sensors]]\\nname = \"wheel\"\\nkind = \"odom\"\\nkey = \"odom\"\\n')\n"
            "before = sorted(KINDS), 'importlib.metadata' in sys.modules\n"
            "cfg = loads('[[sensors]]\\nname = \"wheel\"\\nkind = \"odom\"\\nkey = \"odom\"\\n\\n'\n"
            "            '[[sensors]]\\nname = \"sonar\"\\nkind = \"altimeter\"\\nkey = \"range\"\\nrange_sigma = 0.2\\n')\n"
            "print(json.dumps([before, sorted(KINDS), type(cfg.sensors[1]).__name__, cfg.sensors[1].range_sigma]))\n")
    env = {"PYTHONPATH": f"{tmp_path / 'site'}:{root}", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, env=env, check=True)
    before, after, table, sigma = json.loads(out.stdout)
    assert before == [["gps", "imu", "odom", "pose"], False]
    # the broken entry is skipped with a warning; another package installed here may add its own kind too
    assert {"altimeter", "gps", "imu", "odom", "pose"} <= set(after) and "broken" not in after, after
    assert (table, sigma) == ("AltimeterSensor", 0.2)


def test_an_entry_point_cannot_replace_a_built_in_kind_nor_name_another_tag():
    from importlib.metadata import EntryPoint

    from fusiond.core.sensors import KINDS, discover, unregister

    imu = KINDS["imu"]
    eps = [EntryPoint("imu", "tests.support.altimeter:AltimeterKind", "fusiond.sensor_kinds"),
           EntryPoint("sonar", "tests.support.altimeter:AltimeterKind", "fusiond.sensor_kinds")]
    try:
        with pytest.warns(RuntimeWarning, match="not a SensorKind named 'sonar'"):
            assert discover(eps) == []
        assert KINDS["imu"] is imu and "sonar" not in KINDS
        added = discover([EntryPoint("altimeter", "tests.support.altimeter:AltimeterKind", "fusiond.sensor_kinds")])
        assert [k.name for k in added] == ["altimeter"] and KINDS["altimeter"] is added[0]
    finally:
        unregister("altimeter")



@pytest.mark.parametrize("two_d, frame, gps, idle", [
    ("false", "body", "", set()),  # the GPS altitude observes the pitch, its track the heading
    ("false", "body", None, {("wheel", "pitch_estimation"), ("imu", "gyro_scale_estimation")}),
    ("false", "world", "", {("wheel", "pitch_estimation")}),
    ("true", "body", "", {("wheel", "pitch_estimation")}),
])
def test_an_estimate_nothing_observes_is_said_at_start_not_printed_as_estimated(two_d, frame, gps, idle):
    """pitch_estimation without an absolute height (or in 2-D, or with a world-frame twist) adds no state, and a
    gyro scale with nothing telling the heading stays at its prior: the core says so once, in the log and the
    replay's summary, and the summary does not print the prior as an estimate."""
    from structlog.testing import capture_logs

    from fusiond.logs import configure

    from fusiond.core import FusionCore
    from tests.support.configs import robot_config
    from tests.support.core_samples import imu, odom

    cfg = robot_config(gps=gps, odom=f'twist_frame = "{frame}"\npitch_estimation = true',
                       imu="gyro_scale_estimation = true", filt=f"two_d_mode = {two_d}")
    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop warnings
    with capture_logs() as logs:
        core = FusionCore(cfg)
    said = {(e["sensor"], e["key"]) for e in logs if e["event"] == "key_without_effect"}
    assert said == idle == {(s, k) for s, k, _ in core.idle_keys}
    core.ingest(odom(1.0, v=1.0, w=0.1))
    core.ingest(imu(1.01, gyro=(0.0, 0.0, 0.1)))
    assert ("gyro_scale" in core.scales) == (("imu", "gyro_scale_estimation") not in idle)
