"""A new sensor kind takes one module and one registry line: the toy altimeter of
tests/support/altimeter.py, registered here, loads from TOML, is fused by the core, decodes from
CDR and is replayed from a ROS 2 bag, with nothing else in fusiond touched."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest
from rosbags.rosbag2 import Writer

from fusiond.codecs import ODOMETRY, DecodeError, typestore
from fusiond.config import ConfigError, loads
from fusiond.core.fusion import FusionCore
from fusiond.core.layout import absolute_height, state_layout
from fusiond.core.sensors import encode_sample, kind_of, make_decoder, register, unregister
from fusiond.replay.run import replay
from tests.support.altimeter import RANGE, AltimeterKind, AltimeterSample, AltimeterSensor, encode_altimeter_sample
from tests.support.core_samples import odom

HEIGHT = 2.0  # m: what the altimeter reads; the odometry says the robot never climbs
NOISE = 0.05  # m: the altimeter's stated noise
TOML = f"""
[filter]
initial_sigma = [1.0, 0.1]

[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"

[[sensors]]
name = "sonar"
kind = "altimeter"
key = "range"
range_sigma = {NOISE}
"""


@pytest.fixture
def altimeter():
    kind = register(AltimeterKind())  # the one registry line a new kind takes
    yield kind
    unregister(kind.name)


def _readings(n: int, rate: float = 10.0, seed: int = 3) -> list[AltimeterSample]:
    rng = random.Random(seed)
    return [AltimeterSample("sonar", 1.0 + i / rate, HEIGHT + rng.gauss(0.0, NOISE)) for i in range(n)]


def _drive(duration: float = 20.0, rate: float = 50.0):
    return [odom(1.0 + i / rate, v=0.5, var=1e-4) for i in range(int(duration * rate))]


def test_an_unregistered_kind_is_a_config_error_naming_the_known_kinds():
    with pytest.raises(ConfigError, match="kind: Invalid value 'altimeter'; valid values: 'odom', 'imu', 'gps'"):
        loads(TOML)


def test_a_registered_kind_loads_from_toml_with_its_own_keys_checked(altimeter):
    cfg = loads(TOML)
    sonar = cfg.sensor("sonar")
    assert isinstance(sonar, AltimeterSensor) and sonar.range_sigma == NOISE
    assert kind_of(sonar) is altimeter
    assert absolute_height(cfg)  # the layout asks the descriptor, as for a GPS altitude
    assert [b.name for b in state_layout(cfg).blocks] == ["pose"]
    with pytest.raises(ConfigError, match="sensor \"sonar\": Object contains unknown field `range_sigm`; did you mean `range_sigma`"):
        loads(TOML.replace("range_sigma =", "range_sigm ="))
    with pytest.raises(ConfigError, match="sensor \"sonar\": range_sigma: must not be negative"):
        loads(TOML.replace(f"range_sigma = {NOISE}", "range_sigma = -1.0"))


def _fuse(cfg, altimeter_on: bool) -> FusionCore:
    core = FusionCore(cfg)
    samples = _drive() + (_readings(200) if altimeter_on else [])
    for s in sorted(samples, key=lambda s: s.stamp):
        step = core.ingest(s)
        assert step.accepted, step.reason
    return core


def test_the_core_pulls_z_to_the_altimeter_within_its_stated_noise(altimeter):
    cfg = loads(TOML)
    core = _fuse(cfg, altimeter_on=True)
    est = core.estimate()
    z_sigma = math.sqrt(est.pose_covariance[14])
    # 200 readings of sigma 0.05 average to 0.0035 m; the filter's z follows them within a few of its sigmas
    assert abs(est.position[2] - HEIGHT) < max(3.0 * z_sigma, NOISE / math.sqrt(200) * 3.0)
    assert z_sigma < NOISE  # and it believes the height better than one reading
    assert est.position[0] == pytest.approx(0.5 * 19.98, abs=0.05)  # the odometry still drives x
    stats = core.stats[core.index["sonar"]]
    assert stats.applied == 200 and stats.rejected == 0
    nis = core.consistency()["sonar/height"]  # its updates go through the core's consistency windows
    lo, hi = nis["nis_bounds"]
    assert nis["updates"] == 200 and lo <= nis["nis_mean"] <= hi  # readings as noisy as stated: consistent
    # without the altimeter the same drive stays on the ground: the pull above is the new kind's
    assert _fuse(cfg, altimeter_on=False).estimate().position[2] == pytest.approx(0.0, abs=1e-6)


def _range_cdr(sample: AltimeterSample) -> bytes:
    return encode_altimeter_sample(sample, "ros2-cdr")


def test_the_daemon_decoder_of_the_kind_reads_its_ros_message(altimeter):
    cfg = loads(TOML)
    decode = kind_of(cfg.sensor("sonar")).decoder(cfg.sensor("sonar"))
    got = decode(_range_cdr(AltimeterSample("sonar", 12.25, 1.75)))
    assert got == AltimeterSample("sonar", 12.25, 1.75)


@pytest.mark.parametrize("encoding", ["json", "msgpack"])
def test_the_kind_registers_its_own_codecs_and_the_codecs_name_no_kind(altimeter, encoding):
    """JSON and msgpack through the kind's ``codec``: the daemon's decoder of a `json` key, the codecs'
    decoder by kind name and their encoder by sample type, none of them written for the altimeter."""
    cfg = loads(TOML.replace('key = "range"', f'key = "range"\nencoding = "{encoding}"'))
    sonar = cfg.sensor("sonar")
    reading = AltimeterSample("sonar", 12.25, 1.75)
    raw = encode_sample(reading, encoding)
    assert raw == encode_altimeter_sample(reading, encoding)
    assert kind_of(sonar).decoder(sonar)(raw) == reading
    assert make_decoder("altimeter", encoding, "sonar")(raw) == reading
    with pytest.raises(DecodeError, match="schema_invalid"):
        make_decoder("altimeter", encoding, "sonar")(encode_sample(_drive(0.1)[0], encoding))


def _toy_bag(tmp_path: Path) -> Path:
    """A ROS 2 bag of 20 s of driving with the altimeter's readings (sensor_msgs/Range on /range)."""
    bag = tmp_path / "toy"
    ts = typestore()
    samples = sorted(_drive() + _readings(200), key=lambda s: s.stamp)
    with Writer(bag, version=9) as writer:
        conns = {"/odom": writer.add_connection("/odom", ODOMETRY, typestore=ts),
                 "/range": writer.add_connection("/range", RANGE, typestore=ts)}
        for s in samples:
            if isinstance(s, AltimeterSample):
                writer.write(conns["/range"], int(s.stamp * 1e9), _range_cdr(s))
            else:
                writer.write(conns["/odom"], int(s.stamp * 1e9), encode_sample(s, "ros2-cdr"))
    return bag


def test_a_bag_with_the_kinds_topic_replays_and_ends_at_the_measured_height(altimeter, tmp_path: Path):
    bag = _toy_bag(tmp_path)
    result = replay([bag], loads(TOML), progress=False, keep_trace=False)
    assert result.core.stats[result.core.index["sonar"]].applied == 200
    final = result.trajectory[-8:]  # t x y z qx qy qz qw of the last published pose
    assert final[3] == pytest.approx(HEIGHT, abs=3.0 * NOISE / math.sqrt(20))
    assert final[1] == pytest.approx(0.5 * 19.98, abs=0.05)


def test_info_and_init_name_the_kind_that_reads_a_topic_no_built_in_kind_reads(altimeter, tmp_path: Path):
    """A topic whose type only a kind from another package reads: `fusiond info` says which kind, and `fusiond init`
    says which table to add for it (its keys being that package's), rather than "not used"."""
    from fusiond.bag_info import inspect_bags, topic_use
    from fusiond.init_config import generate_config

    bag = _toy_bag(tmp_path)
    info = inspect_bags([bag])
    (t,) = [t for t in info.topics if t.topic == "/range"]
    assert topic_use(t) == 'altimeter sensor: kind = "altimeter", from an installed package'
    assert ('# /range (sensor_msgs/msg/Range): the installed kind "altimeter" reads it: add a [[sensors]] table '
            'with kind = "altimeter" and key = "range"') in generate_config(info, [str(bag)])


def test_the_doctor_names_the_noise_key_the_kind_names_for_its_channel(altimeter):
    """The kind has no check of its own in the doctor: its channel's NIS verdict names the key its kind says
    states that channel's noise (``noise_key``), here a range_sigma stated ten times below the readings' noise."""
    from fusiond.replay.run import run_samples

    cfg = loads(TOML.replace(f"range_sigma = {NOISE}", f"range_sigma = {NOISE / 10}"))
    result = run_samples(sorted(_drive() + _readings(200), key=lambda s: s.stamp), cfg)
    (v,) = [v for v in result.verdicts() if (v.sensor, v.channel) == ("sonar", "height")]
    assert v.level == "warn" and v.key == "sensors.sonar.range_sigma" and "nis_high" in v.message, v
    # stated as the readings' noise: consistent, and nothing named
    (ok,) = [v for v in run_samples(sorted(_drive() + _readings(200), key=lambda s: s.stamp), loads(TOML)).verdicts()
             if (v.sensor, v.channel) == ("sonar", "height")]
    assert ok.level == "ok" and not ok.key, ok
