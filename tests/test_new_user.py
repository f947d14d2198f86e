"""What a new user hit (issue 28), each through the real CLI: `fusiond.cli.main([...])` in-process with
the captured output, or the installed `fusiond` in a process where one is needed (the daemon)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fusiond.cli import main

ROOT = Path(__file__).resolve().parents[1]
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


# -- 6. --no-multicast on every command that opens a session ----------------------------------------------

SESSION_COMMANDS = {
    "run": ["run", "--config", "c.toml"],
    "play": ["play", "b.bag", "--config", "c.toml"],
    "health": ["health"],
    "set-pose": ["set-pose", "1", "2"],
    "monitor": ["monitor"],
    "calibrate-imu": ["calibrate-imu"],
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
    import fusiond.bench as bench

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
