"""What the CLI says, where: human output (summaries, tables) on stdout and log lines on stderr; a ROS 2 bag
cut short gets one plain sentence naming the tools that recover it (not ROS 1's `rosbag reindex`).
Through the real CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.rosbag2 import Writer

from fusiond.codecs import TYPESTORE
from fusiond.config import load
from fusiond.replay.bag import iter_raw_cdr

ROOT = Path(__file__).resolve().parents[2]
F110 = ROOT.parent / "shared" / "data" / "f110_ds2"

pytestmark = pytest.mark.e2e


def fusiond(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiond", *args], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)


def _ros2_copy(jackal_bag: Path, out: Path, cfg) -> Path:
    """The Jackal bag's configured topics as a ROS 2 (SQLite) bag."""
    with Writer(out, version=9) as writer:
        conns = {}
        for t, sensor, cdr in iter_raw_cdr([jackal_bag], cfg.sensors):
            if sensor.name not in conns:
                msgtype = "nav_msgs/msg/Odometry" if sensor.name == "wheel" else "sensor_msgs/msg/Imu"
                conns[sensor.name] = writer.add_connection("/" + sensor.key, msgtype, typestore=TYPESTORE)
            writer.write(conns[sensor.name], t, cdr)
    return out


def test_a_ros2_bag_cut_short_gets_one_plain_sentence_naming_the_right_tools(jackal_bag, tmp_path):
    config = ROOT / "examples" / "jackal.toml"
    bag = _ros2_copy(jackal_bag, tmp_path / "ros2", load(config))
    proc = fusiond("replay", str(bag), "--config", str(config), "--quiet")
    assert proc.returncode == 0, proc.stderr  # whole, it replays
    db3 = next(bag.glob("*.db3"))
    data = db3.read_bytes()
    db3.write_bytes(data[: len(data) // 2])  # the recorder killed halfway
    proc = fusiond("replay", str(bag), "--config", str(config), "--quiet")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "damaged or cut short" in lines[0] and "sqlite3 IN.db3 .dump" in lines[0] and "replay OUT.db3" in lines[0]
    assert "rosbag reindex" not in lines[0].replace("ros2 bag reindex", "")
    assert "Traceback" not in proc.stderr and proc.stdout == ""


@pytest.mark.skipif(not F110.exists(), reason=f"the F1/10 recording is not in {F110} (see docs/RESULTS.md)")
@pytest.mark.parametrize("command, extra", [
    ("replay", ["--advice-budget-s", "0"]),
    ("doctor", ["--advice-budget-s", "0"]),
    ("tune", ["--out", "{tmp}/tuned.toml", "--budget-s", "3", "--quiet"]),
])
def test_summaries_on_stdout_log_lines_on_stderr(tmp_path, command, extra):
    """The F1/10 recording's logging gap makes the core log `time_jump_forward` (a warning): it goes to
    stderr as a JSON line (stderr is no terminal here), never into the summary or table on stdout."""
    args = [a.format(tmp=tmp_path) for a in extra]
    proc = fusiond(command, str(F110), "--config", str(ROOT / "examples" / "f110.toml"), *args)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip()
    for line in proc.stdout.splitlines():
        assert not line.lstrip().startswith("{") and '"event"' not in line, line
    events = [json.loads(line)["event"] for line in proc.stderr.splitlines() if line.startswith("{")]
    assert "time_jump_forward" in events
