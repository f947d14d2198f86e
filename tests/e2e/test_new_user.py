"""What a new user runs into, each through the real CLI: `fusiond.cli.main([...])` in-process with
the captured output, or the installed `fusiond` in a process where one is needed (the daemon)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fusiond.cli import main

ROOT = Path(__file__).resolve().parents[2]
JACKAL = ROOT / "data" / "jackal_test2.bag"
JACKAL_TOML = ROOT / "examples" / "jackal.toml"
FUSIOND = Path(sys.executable).with_name("fusiond")
PNG = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)) * 8


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """main(argv) in-process: (exit code, stdout, stderr); an argparse exit is an exit code too."""
    try:
        code = main(list(argv))
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 2
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def write_config(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# -- 1. a file that is not a bag: one line, exit 2 ----------------------------------------------------------

def _not_bags(tmp_path: Path) -> list[Path]:
    png = tmp_path / "photo.bag"
    png.write_bytes(PNG)  # a PNG renamed .bag
    mcap = tmp_path / "noise.mcap"
    mcap.write_bytes(os.urandom(4096))
    db3 = tmp_path / "ros2_dir"
    db3.mkdir()
    (db3 / "ros2_dir_0.db3").write_bytes(os.urandom(4096))
    yaml_dir = tmp_path / "bad_meta"
    yaml_dir.mkdir()
    (yaml_dir / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n  unclosed\n")
    damaged = tmp_path / "damaged.bag"  # a real bag with a chunk overwritten: fails while reading
    data = bytearray(JACKAL.read_bytes())
    data[200_000:220_000] = bytes(range(256)) * 78 + bytes(32)
    damaged.write_bytes(bytes(data))
    return [png, mcap, db3, yaml_dir, damaged]


def test_not_a_bag_is_one_line_exit_2_for_replay(tmp_path, capsys):
    for bag in _not_bags(tmp_path):
        code, out, err = run_cli(capsys, "replay", str(bag), "--config", str(JACKAL_TOML), "--quiet")
        line = one_line(err)
        assert code == 2, (bag, err)
        assert line.startswith(f"fusiond: {bag}: not a readable ROS 1/ROS 2 bag ("), line
        assert line.endswith(")"), line


def test_not_a_bag_is_one_line_exit_2_for_calibrate_imu(tmp_path, capsys):
    for bag in _not_bags(tmp_path)[:2]:
        code, _, err = run_cli(capsys, "calibrate-imu", "--bag", str(bag), "--config", str(JACKAL_TOML))
        assert code == 2 and "not a readable ROS 1/ROS 2 bag" in one_line(err)


def test_not_a_bag_is_one_line_exit_2_for_play_before_any_session(tmp_path, capsys):
    """play refuses the file before it opens Zenoh (nothing to play, nothing to wait for)."""
    png = _not_bags(tmp_path)[0]
    code, _, err = run_cli(capsys, "play", str(png), "--config", str(JACKAL_TOML), "--no-multicast", "--wait", "0")
    assert code == 2 and one_line(err).startswith(f"fusiond: {png}: not a readable ROS 1/ROS 2 bag (")


# -- 7. config errors name the sensor by its name ---------------------------------------------------------

ODOM_IMU = '[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n[[sensors]]\nname = "imu"\nkind = "imu"\nkey = "imu"\n'


@pytest.mark.parametrize("extra, needle", [
    ('orientation = "sideways"\n', 'sensor "imu": orientation: Invalid enum value'),  # msgspec's path
    ("orientaton = \"off\"\n", 'sensor "imu": Object contains unknown field `orientaton`; did you mean `orientation`?'),
    ("yaw_offset = 20\n", 'sensor "imu": yaw_offset: 20.0 is beyond'),  # fusiond's own checks
    ("timeout_s = -1.0\n", 'sensor "imu": timeout_s: must not be negative'),
    ('key = "/imu"\n', None),  # a duplicate key= line is invalid TOML: not about sensors at all
])
def test_config_errors_name_the_sensor(tmp_path, capsys, extra, needle):
    cfg = write_config(tmp_path, ODOM_IMU + extra)
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet")
    line = one_line(err)
    assert code == 2
    assert "sensors[1]" not in line
    if needle:
        assert needle in line, line


@pytest.mark.parametrize("text, needle", [
    # a key of another table names that table, not a look-alike here
    (ODOM_IMU + "two_d_mode = true\n", 'sensor "imu": Object contains unknown field `two_d_mode`; it is a key of '
                                       "[filter]"),
    # a migrating user's robot_localization / robot_pose_ekf parameter names fusiond's and the migration guide
    (ODOM_IMU + "relative = true\n", '`relative`; a robot_localization / robot_pose_ekf parameter (fusiond: '
                                     '`orientation = "relative"` (an IMU)'),
    ("[filter]\nsensor_timeout = 1.0\n" + ODOM_IMU, "`sensor_timeout`; a robot_localization / robot_pose_ekf "
                                                    "parameter (fusiond: `timeout_s`, per sensor; docs/MIGRATION.md)"),
    ("[filter]\nodom0_config = [true]\n" + ODOM_IMU, "`odom0_config`; a robot_localization / robot_pose_ekf "
                                                     "parameter (fusiond: a [[sensors]] table per sensor; its config "
                                                     "booleans are `twist_measured`"),
    # a vector given as one number says how many
    (ODOM_IMU.replace('key = "odom"\n', 'key = "odom"\ntwist_noise = 0.1\n'),
     'sensor "wheel": twist_noise: Expected `array | null`, got `float`; write a list of 6 numbers in [ ]'),
    # [sensors] for [[sensors]]: one table (a document msgspec refuses), or a table then a list (TOML refuses)
    ('[sensors]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n',
     "sensors: Expected `array`, got `object`; each sensor is a [[sensors]] table (double brackets), not [sensors]"),
    (ODOM_IMU.replace("[[sensors]]", "[sensors]", 1),
     "invalid TOML: Cannot overwrite a value (at line 5, column 10); each sensor is a [[sensors]] table"),
])
def test_config_errors_say_where_a_key_belongs(tmp_path, capsys, text, needle):
    cfg = write_config(tmp_path, text)
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet")
    line = one_line(err)
    assert code == 2 and needle in line, line


def test_config_errors_keep_the_index_where_a_name_cannot_tell_the_tables_apart(tmp_path, capsys):
    cfg = write_config(tmp_path, ODOM_IMU.replace('name = "imu"', 'name = "wheel"'))
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet")
    assert code == 2 and "sensors[1].name: duplicate sensor name 'wheel'" in one_line(err)


# -- 2. `fusiond run` without sensors is refused before Zenoh -------------------------------------------

def test_run_without_sensors_is_refused_at_once(tmp_path):
    cfg = write_config(tmp_path, '[zenoh]\nmode = "peer"\nmulticast_scouting = false\n')
    started = time.monotonic()
    proc = subprocess.run([str(FUSIOND), "run", "--config", str(cfg)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    line = one_line(proc.stderr)
    assert line.startswith(f"fusiond: config error: {cfg}: no [[sensors]] configured"), line
    assert time.monotonic() - started < 60


def test_run_without_sensors_does_not_import_zenoh(tmp_path, capsys, monkeypatch):
    import fusiond.transport.daemon as daemon

    monkeypatch.setattr(daemon, "run", lambda *a, **k: pytest.fail("the daemon was started"))
    cfg = write_config(tmp_path, "")
    code, _, err = run_cli(capsys, "run", "--config", str(cfg))
    assert code == 2 and "no [[sensors]] configured" in one_line(err)


@pytest.mark.parametrize("command,verb", [("replay", "replay"), ("doctor", "replay"), ("tune", "tune"),
                                          ("play", "play")])
def test_a_bag_command_without_sensors_says_so(tmp_path, capsys, command, verb):
    cfg = write_config(tmp_path, "")
    extra = ["--out", str(tmp_path / "t.toml")] if command == "tune" else ["--no-multicast"] if command == "play" else []
    code, out, err = run_cli(capsys, command, str(JACKAL), "--config", str(cfg), *extra)
    assert code == 2 and out == ""
    assert one_line(err).startswith(f"fusiond: config error: {cfg}: no [[sensors]] configured: nothing to {verb}")


# -- 6. --no-multicast on every command that opens a session ----------------------------------------------

SESSION_COMMANDS = {
    "run": ["run", "--config", "c.toml"],
    "play": ["play", "b.bag", "--config", "c.toml"],
    "health": ["health"],
    "set-pose": ["set-pose", "1", "2"],
    "monitor": ["monitor"],
    "calibrate-imu": ["calibrate-imu"],
    "bench": ["bench", "--latency"],
    "bench-latency": ["bench-latency"],
}


@pytest.mark.parametrize("command", sorted(SESSION_COMMANDS))
def test_every_session_command_takes_no_multicast(command):
    from fusiond.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(SESSION_COMMANDS[command]).no_multicast is False
    assert parser.parse_args(SESSION_COMMANDS[command] + ["--no-multicast"]).no_multicast is True


def test_run_no_multicast_turns_the_configs_scouting_off(tmp_path, capsys, monkeypatch):
    import fusiond.transport.daemon as daemon

    seen = []
    monkeypatch.setattr(daemon, "run", lambda cfg, **_: seen.append(cfg.zenoh.multicast_scouting) or 0)
    assert run_cli(capsys, "run", "--config", str(JACKAL_TOML))[0] == 0
    assert run_cli(capsys, "run", "--config", str(JACKAL_TOML), "--no-multicast")[0] == 0
    assert seen == [True, False]


def test_tools_no_multicast_reaches_the_zenoh_config(tmp_path, capsys, monkeypatch):
    """health, set-pose, monitor, play and calibrate-imu share the tool session: the flag reaches its config."""
    import fusiond.transport.session as session

    seen = []
    real = session.client_config

    def spy(zc, **kw):
        seen.append(zc.multicast_scouting)
        return real(zc, **kw)

    monkeypatch.setattr(session, "client_config", spy)
    code, _, err = run_cli(capsys, "health", "--no-multicast", "--timeout", "0.5")
    assert code == 1 and seen == [False]


def test_the_latency_benchmarks_sessions_never_scout():
    """bench-latency and bench --latency take --no-multicast like every session command; their daemon and load
    generator share the benchmark's config, whose sessions meet on loopback without multicast."""
    from fusiond.config import loads
    from benchmarks.bench_latency import _config_text, free_port

    zc = loads(_config_text(free_port()), "<bench>").zenoh
    assert zc.multicast_scouting is False and all(ep.startswith("tcp/127.0.0.1:") for ep in zc.listen)


def test_health_with_no_multicast_and_no_daemon_gives_up_quickly(tmp_path, capsys):
    started = time.monotonic()
    code, out, err = run_cli(capsys, "health", "--no-multicast", "--timeout", "0.5")
    took = time.monotonic() - started
    assert code == 1 and out == ""
    assert "no health answer" in one_line(err)
    assert took < 10, took


# -- 4. --version -----------------------------------------------------------------------------------------

def test_version(capsys):
    from importlib.metadata import version

    code, out, err = run_cli(capsys, "--version")
    assert code == 0 and err == ""
    assert out == f"fusiond {version('fusiond')}\n"


def test_version_from_the_installed_script():
    proc = subprocess.run([str(FUSIOND), "--version"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.startswith("fusiond ") and proc.stdout.split()[1][0].isdigit()


# -- 11. bench's default bag is the repo's own -------------------------------------------------------------

def test_bench_defaults_to_the_bag_in_the_repo_from_any_directory(tmp_path, capsys, monkeypatch):
    import benchmarks.bench as bench

    seen = []
    monkeypatch.setattr(bench, "run", lambda bag, config, cfg, quick=False: seen.append((bag, config)) or {})
    monkeypatch.setattr(bench, "format_table", lambda result: "table")
    monkeypatch.chdir(tmp_path)  # not the repo: the defaults must not be relative to the current directory
    code, out, err = run_cli(capsys, "bench", "--quick")
    assert code == 0, err
    assert seen == [(JACKAL, JACKAL_TOML)] and JACKAL.is_file()


def test_bench_with_a_missing_bag_is_one_line_exit_2(tmp_path, capsys):
    missing = tmp_path / "nope.bag"
    code, out, err = run_cli(capsys, "bench", "--bag", str(missing), "--config", str(JACKAL_TOML))
    assert code == 2 and out == ""
    assert one_line(err) == f"fusiond: bench: no such bag {missing}; give one with --bag"


def _no_benchmark(monkeypatch):
    import benchmarks.bench as bench

    monkeypatch.setattr(bench, "run", lambda *a, **k: pytest.fail("benchmarked input that replay refuses"))


def test_bench_refuses_a_file_that_is_no_bag_before_benchmarking(tmp_path, capsys, monkeypatch):
    _no_benchmark(monkeypatch)
    png = _not_bags(tmp_path)[0]
    code, out, err = run_cli(capsys, "bench", "--bag", str(png), "--config", str(JACKAL_TOML), "--quick")
    assert code == 2 and out == ""
    assert one_line(err).startswith(f"fusiond: bench: {png}: not a readable ROS 1/ROS 2 bag ("), err


def test_bench_refuses_a_config_without_odometry(tmp_path, capsys, monkeypatch):
    _no_benchmark(monkeypatch)
    for text in ("", '[[sensors]]\nname = "imu"\nkind = "imu"\nkey = "imu/data"\n'):
        cfg = write_config(tmp_path, text)
        code, out, err = run_cli(capsys, "bench", "--config", str(cfg), "--quick")
        assert code == 2 and out == "", err
        line = one_line(err)
        assert line.startswith("fusiond: ") and ("no odometry sensor" in line or "exactly one odom" in line), line


def test_bench_refuses_a_world_frame_topic_the_bag_lacks(tmp_path, capsys, monkeypatch):
    _no_benchmark(monkeypatch)
    cfg = _jackal_config(tmp_path, extra='[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "gps/fix"\n')
    code, out, err = run_cli(capsys, "bench", "--config", str(cfg), "--quick")
    assert code == 2 and out == ""
    assert "fusiond: bench: the topic /gps/fix (sensor 'gps') that defines the world frame" in one_line(err)


# -- 3. an absent topic names the bag's topics and the one it was likely meant to be ----------------------

def _jackal_config(tmp_path: Path, odom: str = "jackal_velocity_controller/odom", imu: str = "imu/data",
                   extra: str = "") -> Path:
    return write_config(tmp_path, f'[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "{odom}"\n'
                                  f'[[sensors]]\nname = "imu"\nkind = "imu"\nkey = "{imu}"\n'
                                  f'orientation = "roll_pitch"\nangular_velocity = true\n{extra}')


def test_did_you_mean():
    from fusiond.replay.bag import did_you_mean

    topics = ["/imu/data", "/jackal_velocity_controller/odom", "/gps/fix"]
    assert did_you_mean("imu/dta", topics) == " (did you mean /imu/data?)"
    assert did_you_mean("/imu/data_raw", topics) == " (did you mean /imu/data?)"
    assert did_you_mean("jackal_velocity_controler/odom", topics) == " (did you mean /jackal_velocity_controller/odom?)"
    assert did_you_mean("gps/fx", ["gps/fix"]) == " (did you mean gps/fix?)"  # the bag's own spelling
    assert did_you_mean("camera/image", topics) == ""
    assert did_you_mean("imu", []) == ""


def test_an_absent_imu_topic_allowed_warns_naming_the_bag_topics_and_a_close_one(tmp_path, capsys):
    tum = tmp_path / "out.tum"
    cfg = _jackal_config(tmp_path, imu="imu/dta")
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet", "--tum", str(tum),
                           "--allow-missing")
    assert code == 0, err  # still a replay: odometry alone
    warning = one_line(err)
    assert warning.startswith("fusiond: warning: sensor 'imu': topic /imu/dta is not in the bag"), warning
    assert "(did you mean /imu/data?)" in warning
    assert "/imu/data [sensor_msgs/msg/Imu]" in warning and "/jackal_velocity_controller/odom" in warning
    assert len(tum.read_text().splitlines()) == 3060  # it ran


def test_an_absent_odometry_topic_is_an_error_with_a_close_one(tmp_path, capsys):
    cfg = _jackal_config(tmp_path, odom="jackal_velocity_controler/odom")
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet")
    line = one_line(err)
    assert code == 2
    assert "the odometry topic /jackal_velocity_controler/odom" in line
    assert "(did you mean /jackal_velocity_controller/odom?)" in line and "/imu/data [sensor_msgs/msg/Imu]" in line


def test_an_unlike_topic_gets_no_guess(tmp_path, capsys):
    cfg = _jackal_config(tmp_path, imu="camera/image_raw")
    code, _, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg), "--quiet")
    assert code == 2 and "did you mean" not in one_line(err) and "/camera/image_raw" in err


def _bag_with_gps(path: Path) -> None:
    """The Jackal's first 300 odometry and IMU messages as a ROS 2 bag, with NavSatFix fixes on /gps/fix."""
    from rosbags.rosbag2 import Writer

    from fusiond.codecs import IMU, NAVSATFIX, ODOMETRY, TYPESTORE
    from fusiond.core.sensors.gps.codec import encode_gps_sample
    from fusiond.config import ImuSensor, OdomSensor
    from fusiond.replay.bag import iter_raw_cdr
    from fusiond.core.sensors import GpsSample

    sensors = [OdomSensor(name="wheel", key="jackal_velocity_controller/odom"), ImuSensor(name="imu", key="imu/data")]
    rows = list(iter_raw_cdr([JACKAL], sensors))[:300]
    with Writer(path, version=9) as writer:
        conns = {}
        for t, sensor, cdr in rows:
            msgtype = ODOMETRY if sensor.name == "wheel" else IMU
            if sensor.key not in conns:
                conns[sensor.key] = writer.add_connection("/" + sensor.key, msgtype, typestore=TYPESTORE)
            writer.write(conns[sensor.key], t, cdr)
        gps = writer.add_connection("/gps/fix", NAVSATFIX, typestore=TYPESTORE)
        for i in range(5):
            fix = GpsSample(sensor="gps", stamp=rows[0][0] * 1e-9 + i, latitude=48.0, longitude=11.0, altitude=500.0)
            writer.write(gps, rows[0][0] + i * 1_000_000_000, encode_gps_sample(fix, "ros2-cdr"))


def test_an_absent_gps_topic_names_the_close_one(tmp_path, capsys):
    """A GPS defines the world frame: absent, nothing would be published, so it is an error (as before);
    the message says which topic of the bag it likely meant."""
    bag = tmp_path / "with_gps"
    _bag_with_gps(bag)
    gps = '[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "{}"\n'
    code, _, err = run_cli(capsys, "replay", str(bag), "--config", str(_jackal_config(tmp_path, extra=gps.format("gps/fix"))),
                           "--quiet")
    assert code in (0, 1) and "did you mean" not in err  # the right key: no complaint about topics
    code, _, err = run_cli(capsys, "replay", str(bag), "--config", str(_jackal_config(tmp_path, extra=gps.format("gps/fx"))),
                           "--quiet")
    line = one_line(err)
    assert code == 2 and "/gps/fx" in line and "(did you mean /gps/fix?)" in line and "/gps/fix [" in line


# -- 8. calibrate-imu's snippet pastes into the existing tables --------------------------------------------

ROBOT = """[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"

[[sensors]]
name = "front_imu"
kind = "imu"
key = "imu/data"
orientation = "roll_pitch"
angular_velocity = true

[filter]
nis_window = 50
"""


def _static_imu_bag(path: Path, n: int = 3000, rate: float = 100.0) -> None:
    from rosbags.rosbag2 import Writer

    from fusiond.codecs import IMU, TYPESTORE
    from fusiond.estimator import rotation as rot
    from fusiond.core.sensors import ImuSample, encode_sample

    rng = np.random.default_rng(3)
    cov = (1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6)
    with Writer(path, version=9) as writer:
        conn = writer.add_connection("/imu/data", IMU, typestore=TYPESTORE)
        for k in range(n):
            t = 100.0 + k / rate
            q = rot.from_rpy(rng.normal(0, 0.01), rng.normal(0, 0.02), 1.0 + rng.normal(0, 0.05))
            w = tuple(b + rng.normal(0, 0.003) for b in (0.001, -0.002, 0.003))
            acc = (rng.normal(0, 0.02), rng.normal(0, 0.02), 9.81 + rng.normal(0, 0.02))
            sample = ImuSample("imu", t, tuple(q), cov, w, cov, acc, cov)
            writer.write(conn, int(t * 1e9), encode_sample(sample, "ros2-cdr"))


def paste(config: str, snippet: str) -> str:
    """Do what the snippet's comments say: each block's key lines at the end of the table it names."""
    import re

    lines = config.splitlines()
    for block in snippet.split("\n\n"):
        rows = block.splitlines()
        target = next(r for r in rows if r.startswith("# paste into "))
        keys = rows[rows.index(target) + 1:]
        assert keys and all(re.match(r"^[a-z_]+ = \S", k) for k in keys), keys  # key = value lines only
        named = re.match(r'# paste into the \[\[sensors\]\] table named "([^"]+)"', target)
        if named:
            start = lines.index(f'name = "{named.group(1)}"')
        else:
            assert target.startswith("# paste into the [filter] table")
            start = lines.index("[filter]")
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
        while lines[end - 1] == "":
            end -= 1
        lines[end:end] = keys
    return "\n".join(lines) + "\n"


def test_calibrate_imu_snippet_pastes_into_the_named_sensor_table(tmp_path, capsys):
    from fusiond.config import loads

    bag = tmp_path / "static"
    _static_imu_bag(bag)
    cfg = write_config(tmp_path, ROBOT)
    code, out, err = run_cli(capsys, "calibrate-imu", "--bag", str(bag), "--config", str(cfg),
                             "--sensor", "front_imu", "--duration", "20")
    assert code == 0, err
    assert "[[sensors]]" not in [line.split("#")[0].strip() for line in out.splitlines()]  # no header to clash
    assert not any(line.strip().startswith("[") for line in out.splitlines())
    assert '# paste into the [[sensors]] table named "front_imu"' in out
    pasted = loads(paste(ROBOT, out.strip()))
    assert [s.name for s in pasted.sensors] == ["wheel", "front_imu"]  # no sensor added
    imu = pasted.sensor("front_imu")
    assert imu.orientation_noise == pytest.approx((0.01, 0.02, 0.05), rel=0.1)
    assert imu.gyro_noise == pytest.approx(0.003, rel=0.1)
    assert pasted.filter.nis_window == 50 and pasted.filter.gyro_bias_sigma == pytest.approx(0.006, rel=0.1)


# -- 9. the monitor: no "ok" beside a NIS outside its bounds, a window column that agrees with its text -------

def _records(nis_values, dof=2, channel="orientation", t0=0.0, learning=False):
    from fusiond.core.diagnostics import DiagnosticsRecord

    components = ["roll", "pitch", "yaw"][:dof]
    return [DiagnosticsRecord(t0 + 0.02 * k, "imu", components, [0.01] * dof, [1e-4] * dof, float(v), dof, False,
                              channel=channel, learning=learning) for k, v in enumerate(nis_values)]


def _view(records, window=50):
    from fusiond.monitor import DaemonView

    view = DaemonView("", window=window)
    for k, r in enumerate(records):
        view.add(r, now=100.0 + 0.02 * k)
    return view.snapshot(now=100.0 + 0.02 * len(records))


def _inside(mean, bounds):
    return bounds[0] <= mean <= bounds[1]


def _assert_consistent(row):
    """Each verdict is the one its own mean and bounds give, and the 'now:' note is the window's verdict."""
    for mean, bounds, verdict in ((row["nis_mean"], row["nis_bounds"], row["verdict"]),
                                  (row["window_nis_mean"], row["window_nis_bounds"], row["window_verdict"])):
        if verdict == "ok":
            assert mean is not None and _inside(mean, bounds), row
        elif verdict == "nis_high":
            assert mean > bounds[1], row
        elif verdict == "nis_low":
            assert mean < bounds[0], row
    note = row["now_note"]
    if note:
        assert note.startswith(f"now: {row['window_verdict']} since"), row
    elif row["window_verdict"] not in ("no_updates", row["verdict"]):
        pytest.fail(f"the window says {row['window_verdict']} and the text says nothing: {row}")


def test_monitor_whole_run_ok_with_a_high_window(capsys):
    """1000 good updates then 50 whose NIS is 5x: the run is still ok, the window is not; the row shows the
    run's mean and bounds beside the run's 'ok', the window's beside the window's verdict."""
    from fusiond.monitor import plain_lines

    snap = _view(_records([2.0] * 1000 + [10.0] * 50))
    row = snap["channels"][0]
    assert row["verdict"] == "ok" and _inside(row["nis_mean"], row["nis_bounds"])
    assert row["nis_mean"] == pytest.approx((2000 + 500) / 1050)
    assert row["window_verdict"] == "nis_high" and row["window_nis_mean"] == pytest.approx(10.0)
    assert row["window_nis_mean"] > row["window_nis_bounds"][1]
    assert row["now_note"].startswith("now: nis_high since")
    _assert_consistent(row)
    line = next(ln for ln in plain_lines([snap], 0.0) if "imu/orientation" in ln)
    assert f"nis={row['nis_mean']:.3f} " in line and "-> ok (now: nis_high since" in line, line
    assert "window_nis=10.000" in line and "-> nis_high rms[" in line, line


def test_monitor_terminal_view_columns_agree(capsys):
    from rich.console import Console

    from fusiond.monitor import render

    snap = _view(_records([2.0] * 1000 + [10.0] * 50))
    console = Console(record=True, width=250, force_terminal=False)
    console.print(render([snap]))
    text = console.export_text()
    header = next(ln for ln in text.splitlines() if "sensor/channel" in ln)
    row_line = next(ln for ln in text.splitlines() if "imu/orientation" in ln)
    cells = row_line.split()
    names = header.split()
    # sensor/channel rate age NIS mean [lo, hi] verdict window NIS [lo, hi] window ...
    assert cells[3] == f"{snap['channels'][0]['nis_mean']:.3f}" and cells[6] == "ok", row_line
    assert cells[7] == "10.000" and cells[10] == "nis_high", row_line
    assert names.index("verdict") < names.index("window"), header


@pytest.mark.parametrize("values", [
    [2.0] * 60,  # ok throughout
    [20.0] * 80,  # high throughout
    [0.01] * 80,  # low throughout
    [20.0] * 30 + [2.0] * 20,  # high run, window recovering
    [2.0] * 300 + [0.01] * 60,  # ok run, low window
])
def test_monitor_rows_are_consistent(values):
    _assert_consistent(_view(_records(values))["channels"][0])


def test_monitor_window_mixing_dofs_is_the_doctors_window():
    """A message without its yaw row (dof 2 among dof 3): the window test of the row is the doctor's, which
    keeps both in the window, rather than a window of the monitor's own restarted at every dof change."""
    records = _records([3.0] * 200, dof=3) + _records([15.0] * 10, dof=2, t0=10.0)
    row = _view(records)["channels"][0]
    stats_mean = (40 * 3.0 + 10 * 15.0) / 50
    assert row["window_nis_mean"] == pytest.approx(stats_mean)
    _assert_consistent(row)


def test_monitor_learning_channel_is_not_judged_in_the_window_either():
    row = _view(_records([50.0] * 40, learning=True))["channels"][0]
    assert row["verdict"] == "learning" and row["window_verdict"] == "learning"
    assert row["window_nis_mean"] is None


# -- 10. the report's innovation panels are scaled to the data -----------------------------------------------

def test_innovation_limits_stay_near_the_bulk():
    from fusiond.replay.report import innovation_limits

    rng = np.random.default_rng(0)
    y = rng.normal(0.0, 0.1, 2000)
    band = np.full(2000, 0.2)
    band[:10] = 500.0  # the first updates: S huge before the state converged
    y[700] = 1e3  # one outlier
    lo, hi = innovation_limits(y, band)
    bulk = np.percentile(np.abs(y), 99)
    assert lo == -hi and bulk < hi < 2.0 * max(bulk, 0.2), (hi, bulk)
    # NaN rows (the gap breaks) are left out; nothing finite: matplotlib's own limits
    assert innovation_limits(np.array([np.nan, 0.1, -0.1]), np.array([np.nan, 0.1, 0.1]))[1] == pytest.approx(0.125)
    assert innovation_limits(np.array([np.nan]), np.array([np.nan])) is None
    assert innovation_limits(np.zeros(5), np.zeros(5)) is None


def _jackal_with_an_imu_outlier(path: Path, roll: float = 0.8, messages: int = 1500) -> None:
    from rosbags.rosbag2 import Writer

    import msgspec

    from fusiond.codecs import IMU, ODOMETRY, TYPESTORE
    from fusiond.core.sensors import encode_sample, make_decoder
    from fusiond.config import ImuSensor, OdomSensor
    from fusiond.estimator import rotation as rot
    from fusiond.replay.bag import iter_raw_cdr

    sensors = [OdomSensor(name="wheel", key="jackal_velocity_controller/odom"), ImuSensor(name="imu", key="imu/data")]
    rows = list(iter_raw_cdr([JACKAL], sensors))[:messages]
    decode = make_decoder("imu", "ros2-cdr", "imu")
    imu_rows = [i for i, (_, s, _) in enumerate(rows) if s.name == "imu"]
    bad = imu_rows[len(imu_rows) // 2]
    sample = decode(rows[bad][2])
    r, p, y = rot.to_rpy(np.asarray(sample.orientation))
    sample = msgspec.structs.replace(sample, orientation=tuple(rot.from_rpy(r + roll, p, y)))
    rows[bad] = (rows[bad][0], rows[bad][1], encode_sample(sample, "ros2-cdr"))
    with Writer(path, version=9) as writer:
        conns = {}
        for t, s, cdr in rows:
            if s.key not in conns:
                conns[s.key] = writer.add_connection("/" + s.key, ODOMETRY if s.name == "wheel" else IMU,
                                                     typestore=TYPESTORE)
            writer.write(conns[s.key], t, cdr)


def _panel_limits(monkeypatch) -> dict[str, list[tuple[str, tuple[float, float]]]]:
    """(y label, y-limits) of every panel of each figure the report saves, by file name."""
    from matplotlib.figure import Figure

    saved: dict = {}
    real = Figure.savefig

    def spy(self, fname, *a, **k):
        saved[Path(fname).name] = [(ax.get_ylabel(), ax.get_ylim()) for ax in self.axes]
        return real(self, fname, *a, **k)

    monkeypatch.setattr(Figure, "savefig", spy)
    return saved


def test_report_innovation_panels_are_scaled_to_the_bulk_not_an_outlier(tmp_path, capsys, monkeypatch):
    bag = tmp_path / "outlier"
    _jackal_with_an_imu_outlier(bag, roll=0.8)
    saved = _panel_limits(monkeypatch)
    out = tmp_path / "report"
    code, _, err = run_cli(capsys, "replay", str(bag), "--config", str(JACKAL_TOML), "--report", str(out), "--quiet")
    assert code == 0, err
    assert (out / "innovations.png").is_file()
    panels = dict(saved["innovations.png"])
    roll = panels["imu/orientation\nroll"]
    assert roll[0] == -roll[1]
    assert 0.005 < roll[1] < 0.1, roll  # the 0.8 rad outlier does not set the scale


# -- 5. `doctor` and `report` subcommands: replay's own machinery ---------------------------------------------

def _without_timing(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if not ln.startswith("messages ")]  # wall time differs run to run


def test_doctor_prints_the_verdicts_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "doctor", str(JACKAL), "--config", str(JACKAL_TOML))
    assert code == 0, err
    assert list(tmp_path.iterdir()) == []  # no files
    assert "doctor WARN    wheel/yaw_rate" in out and "doctor ok      imu/orientation" in out
    assert "report " not in out
    code, replayed, _ = run_cli(capsys, "replay", str(JACKAL), "--config", str(JACKAL_TOML))
    assert code == 0 and _without_timing(out) == _without_timing(replayed)  # the same replay, the same words


def test_doctor_on_bad_input_exits_2(tmp_path, capsys):
    png = tmp_path / "photo.bag"
    png.write_bytes(PNG)
    code, _, err = run_cli(capsys, "doctor", str(png), "--config", str(JACKAL_TOML))
    assert code == 2 and "not a readable ROS 1/ROS 2 bag" in one_line(err)
    code, _, err = run_cli(capsys, "doctor", str(JACKAL), "--config", str(tmp_path / "none.toml"))
    assert code == 2 and "cannot read config" in one_line(err)


def test_report_writes_the_html_report_like_replay_report(tmp_path, capsys):
    out_dir = tmp_path / "report"
    code, out, err = run_cli(capsys, "report", str(JACKAL), "--config", str(JACKAL_TOML), "--out", str(out_dir))
    assert code == 0, err
    assert sorted(p.name for p in out_dir.iterdir()) == ["index.html", "innovations.png", "overview.png"]
    assert f"report      {out_dir / 'index.html'}" in out
    page = (out_dir / "index.html").read_text()
    assert 'id="verdicts"' in page and "wheel/yaw_rate" in page
    code, out, _ = run_cli(capsys, "report", str(JACKAL), "--config", str(JACKAL_TOML), "--out", str(out_dir),
                           "--quiet")
    assert code == 0 and out == ""


def test_report_refuses_an_out_that_is_a_file_before_replaying(tmp_path, capsys):
    taken = tmp_path / "taken.html"
    taken.write_text("x")
    code, out, err = run_cli(capsys, "report", str(JACKAL), "--config", str(JACKAL_TOML), "--out", str(taken))
    assert code == 2 and "names an existing file" in one_line(err)


def test_doctor_and_report_are_in_the_help(capsys):
    code, out, _ = run_cli(capsys, "--help")
    assert code == 0 and "doctor" in out and "report" in out


def test_a_closed_pipe_is_no_traceback(tmp_path):
    proc = subprocess.Popen([str(FUSIOND), "doctor", str(JACKAL), "--config", str(JACKAL_TOML)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader (`| head`) left before anything was written
    _, err = proc.communicate(timeout=120)
    assert b"Traceback" not in err and b"BrokenPipe" not in err, err.decode()


# -- tune's summary says why the fit ended, in words -----------------------------------------------------------

def test_tune_says_the_fit_stopped_at_its_budget(tmp_path, capsys):
    """A budget shorter than the first replay of the fit part: the fit stops there, and says so."""
    out = tmp_path / "tuned.toml"
    code, text, err = run_cli(capsys, "tune", str(JACKAL), "--config", str(JACKAL_TOML), "--out", str(out),
                              "--keys", "imu.gyro_noise", "--budget-s", "0.05", "--quiet")
    assert code == 0, err
    line = next(ln for ln in text.splitlines() if ln.startswith("fit part "))
    assert line.endswith("; the fit stopped at --budget-s"), line


# -- calibrate-imu that gets no IMU says where it looked ----------------------------------------------------------

def test_calibrate_imu_with_nothing_on_its_key_names_the_key(capsys):
    code, out, err = run_cli(capsys, "calibrate-imu", "--duration", "0.5", "--no-multicast", "--key", "nobody/imu")
    assert code == 1 and out == ""
    line = one_line(err)
    assert line.startswith("fusiond: calibrate-imu: no IMU message on key 'nobody/imu' (ros2-cdr) in 0.5 s"), line


def test_calibrate_imu_on_a_bag_without_the_imu_topic_names_the_bags_topics(tmp_path, capsys):
    cfg = _jackal_config(tmp_path, imu="imu/dta")
    code, out, err = run_cli(capsys, "calibrate-imu", "--bag", str(JACKAL), "--config", str(cfg))
    assert code == 2 and out == ""
    line = one_line(err)
    assert "the IMU topic /imu/dta (sensor 'imu') is not in" in line and "(did you mean /imu/data?)" in line, line
    assert "/jackal_velocity_controller/odom [nav_msgs/msg/Odometry]" in line


# -- the README's flags are the CLI's --------------------------------------------------------------------------

def test_every_flag_the_readme_and_migration_guide_show_is_a_fusiond_flag():
    """A flag the guides show that no command takes would fail a user with argparse's "unrecognized arguments"."""
    import argparse
    import re

    from fusiond.cli import build_parser

    flags: set[str] = set()
    for action in build_parser()._actions:
        flags.update(action.option_strings)
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                for a in sub._actions:
                    flags.update(a.option_strings)
    others = {"--fast": "scripts/test.sh", "--rm": "docker run", "--network": "docker run"}
    for doc in ("README.md", "docs/MIGRATION.md"):
        shown = set(re.findall(r"(?<![\w/.-])(--[a-z][a-z0-9-]*)", (ROOT / doc).read_text()))
        assert shown, doc
        assert not shown - flags - set(others), f"{doc} shows {sorted(shown - flags - set(others))}"


# -- doctor and report take replay's --advice-budget-s (the README names it for the doctor's paste lines) ---------

JACKAL_RL_TOML = ROOT / "examples" / "jackal_rl.toml"


def test_doctor_takes_the_advice_budget(capsys):
    """jackal_rl.toml gets a paste line (fuse the gyro); with budget 0 it is printed unreplayed, by default
    replayed and scored, as `replay` does."""
    code, unreplayed, err = run_cli(capsys, "doctor", str(JACKAL), "--config", str(JACKAL_RL_TOML),
                                    "--advice-budget-s", "0")
    assert code == 0, err
    assert 'name = "imu": angular_velocity = true' in unreplayed and "(replayed:" not in unreplayed
    code, replayed, err = run_cli(capsys, "doctor", str(JACKAL), "--config", str(JACKAL_RL_TOML))
    assert code == 0 and "(replayed: likelihood +" in replayed, err
    code, _, err = run_cli(capsys, "doctor", str(JACKAL), "--config", str(JACKAL_RL_TOML), "--advice-budget-s", "-1")
    assert code == 2 and "--advice-budget-s -1" in one_line(err)


def test_report_takes_the_advice_budget(tmp_path, capsys):
    out_dir = tmp_path / "report"
    code, out, err = run_cli(capsys, "report", str(JACKAL), "--config", str(JACKAL_RL_TOML), "--out", str(out_dir),
                             "--advice-budget-s", "0")
    assert code == 0, err
    assert "angular_velocity = true" in out and "(replayed:" not in out
    assert "angular_velocity = true" in (out_dir / "index.html").read_text()


def test_tune_keeps_every_table_of_the_config_it_tunes(tmp_path, capsys):
    """The tuned config is the user's config with the tuned keys changed: a [state] table (the daemon's
    persisted state) and every other table come through, so nothing but the noise changes."""
    from fusiond.config import load

    cfg = write_config(tmp_path, JACKAL_TOML.read_text() + '\n[state]\npath = "state.bin"\nmax_age_s = 10.0\n'
                       '\n[zenoh]\nmulticast_scouting = false\n\n[ros]\nnode_name = "robot"\n'
                       '\n[output]\nmap_frame = "world"\n\n[filter]\nnis_window = 40\n')
    out = tmp_path / "tuned.toml"
    code, _, err = run_cli(capsys, "tune", str(JACKAL), "--config", str(cfg), "--out", str(out),
                           "--keys", "imu.gyro_noise", "--budget-s", "0.05", "--quiet")
    assert code == 0, err
    before, after = load(cfg), load(out)
    assert after.state.path == "state.bin" and after.state.max_age_s == 10.0
    assert after == before  # the budget ran out before any fit: nothing tuned, nothing else lost


# -- set-pose refuses what it would send wrong, before any session ------------------------------------------------

@pytest.mark.parametrize("argv, needle", [
    (["1", "2", "--sigma", "-0.5", "0.1"], "set-pose --sigma POSITION_M -0.5: a standard deviation must not be"),
    (["1", "2", "--sigma", "0.5", "-0.1"], "set-pose --sigma ATTITUDE_RAD -0.1: a standard deviation must not be"),
    (["nan", "2"], "set-pose x nan: must be a finite number"),
    (["1", "2", "inf"], "set-pose yaw inf: must be a finite number"),
    (["1", "2", "--stamp", "-3"], "set-pose --stamp -3: must not be negative (0: the filter's current time)"),
])
def test_set_pose_refuses_a_value_it_cannot_send_as_typed(capsys, monkeypatch, argv, needle):
    import fusiond.transport.session as session

    monkeypatch.setattr(session, "open_session", lambda *a, **k: pytest.fail("a session was opened"))
    code, out, err = run_cli(capsys, "set-pose", *argv, "--no-multicast")
    assert code == 2 and out == ""
    assert one_line(err).startswith(f"fusiond: {needle}"), err


# -- replay's scoring options are refused when they cannot mean anything, with or without --reference -------------

@pytest.mark.parametrize("option, value, needle", [
    ("--rpe-s", "0", "--rpe-s 0: must be a positive number of seconds"),
    ("--rpe-s", "-1", "--rpe-s -1: must be a positive number of seconds"),
    ("--segment-gap", "nan", "--segment-gap nan: must be a positive number of seconds"),
    ("--segment-gap", "-0.5", "--segment-gap -0.5: must be a positive number of seconds"),
    ("--fuse-every", "0", "--fuse-every 0: must be 1 (fuse every message) or more"),
])
def test_replay_refuses_a_scoring_option_of_no_meaning(tmp_path, capsys, option, value, needle):
    tum = tmp_path / "t.tum"
    code, out, err = run_cli(capsys, "replay", str(JACKAL), "--config", str(JACKAL_TOML), "--quiet",
                             "--tum", str(tum), option, value)
    assert code == 2 and out == "" and not tum.exists()  # refused before the replay
    assert one_line(err) == f"fusiond: {needle}"


# -- durations, timeouts and rates of no meaning are argparse errors, not tracebacks later -----------------------

@pytest.mark.parametrize("argv", [
    ["health", "--timeout", "-1"],  # zenoh would raise "ValueError: negative timeout"
    ["set-pose", "1", "2", "--timeout", "0"],
    ["monitor", "--interval", "0"],
    ["monitor", "--timeout", "nan"],
    ["monitor", "--duration", "-3"],
    ["calibrate-imu", "--duration", "0"],
    ["calibrate-imu", "--start", "-5"],
    ["play", "b.bag", "--config", "c.toml", "--wait", "-1"],
    ["play", "b.bag", "--config", "c.toml", "--duration", "0"],
    ["play", "b.bag", "--config", "c.toml", "--rate", "nan"],  # NaN is no pace
    ["play", "b.bag", "--config", "c.toml", "--rate", "-1"],
    ["bench", "--latency", "--seconds", "0"],
    ["bench-latency", "--seconds", "0"],  # the benchmark would end in a KeyError
    ["bench-latency", "--imu-hz", "0"],
    ["bench-latency", "--odom-hz", "inf"],
    ["bench-latency", "--runs", "0"],
    ["bench-latency", "--runs", "2.5"],
])
def test_an_option_of_no_meaning_is_refused_by_the_parser(capsys, argv):
    code, out, err = run_cli(capsys, *argv, "--no-multicast")
    option = [a for a in argv if a.startswith("--")][-1]  # the one given a value of no meaning
    assert code == 2 and out == "" and "Traceback" not in err
    assert f"error: argument {option}: " in err and ("must be" in err or "is not a" in err), err


def test_bench_with_a_bag_directory_says_it_takes_a_file(tmp_path, capsys, monkeypatch):
    _no_benchmark(monkeypatch)
    ros2 = tmp_path / "ros2_bag"
    ros2.mkdir()
    code, out, err = run_cli(capsys, "bench", "--bag", str(ros2), "--config", str(JACKAL_TOML))
    assert code == 2 and out == ""
    assert one_line(err) == (f"fusiond: bench: --bag {ros2} is a directory (a ROS 2 bag?); bench takes one bag file, "
                             "a ROS 1 .bag or a ROS 2 .mcap")


F110_BAG = ROOT.parent / "shared" / "data" / "f110_ds2"


@pytest.mark.skipif(not F110_BAG.exists(), reason="needs ../shared/data/f110_ds2 (the F1/10 recording)")
def test_a_quiet_replay_logs_no_warnings_unless_a_log_level_asks(capsys, tmp_path):
    """`replay --quiet` writes its files and nothing else (the F1/10 car's config logs twist_component_lost and
    time_jump_forward as warnings): its stderr is empty; `--log-level warning` brings the log lines back."""
    config = str(ROOT / "examples" / "f110_new_user.toml")
    code, out, err = run_cli(capsys, "replay", str(F110_BAG), "--config", config, "--quiet",
                             "--tum", str(tmp_path / "q.tum"))
    assert code == 0 and out == "" and err == "", err
    code, _, err = run_cli(capsys, "replay", str(F110_BAG), "--config", config, "--quiet", "--log-level", "warning",
                           "--tum", str(tmp_path / "w.tum"))
    assert code == 0 and "twist_component_lost" in err, err


def test_an_imu_yaw_that_agrees_is_said_in_words_not_evidence_keys(capsys, tmp_path):
    """The Jackal's IMU yaw fused as absolute agrees with the gyro: the ok verdict says by how much in words (no
    evidence field names such as imu_vs_gyro_wander_rad in the text a user reads)."""
    text = JACKAL_TOML.read_text()
    assert 'orientation = "roll_pitch"' in text
    cfg = tmp_path / "absolute.toml"
    cfg.write_text(text.replace('orientation = "roll_pitch"', 'orientation = "absolute"'))
    code, out, _ = run_cli(capsys, "replay", str(JACKAL), "--config", str(cfg))
    line = next(x for x in out.splitlines() if "imu/orientation:" in x and x.startswith("doctor"))
    assert code == 0 and "agrees with the other heading sources" in line and "wanders" in line, line
    assert "_rad" not in line and "_rad_s" not in line, line
    # without a GPS nothing measures its constant offset (a declination, a mount), and the verdict says so
    assert "its offset (yaw_offset, magnetic_declination) cannot be checked" in line, line
