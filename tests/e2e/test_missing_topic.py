"""A configured topic absent from the bag (a misspelt `/imu/dta`): `replay`, `doctor`, `report` and `tune`
refuse with exit 2 and one message naming the sensor, its topic and the bag's closest topic, before any
output is written; `--allow-missing` replays without it. Through the real CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.e2e

CONFIG = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "jackal_velocity_controller/odom"

[[sensors]]
name = "imu"
kind = "imu"
key = "imu/dta"
orientation = "roll_pitch"
angular_velocity = true
"""


def fusiond(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiond", *args], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)


@pytest.mark.parametrize("command, extra", [
    ("replay", ["--tum", "{tmp}/out.tum"]),
    ("doctor", []),
    ("report", ["--out", "{tmp}/report"]),
    ("tune", ["--out", "{tmp}/tuned.toml", "--budget-s", "5"]),
])
def test_a_misspelt_topic_is_refused_naming_it_with_a_did_you_mean(jackal_bag, tmp_path, command, extra):
    config = tmp_path / "typo.toml"
    config.write_text(CONFIG)
    args = [a.format(tmp=tmp_path) for a in extra]
    proc = fusiond(command, str(jackal_bag), "--config", str(config), *args)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert "sensor 'imu': topic /imu/dta is not in the bag (did you mean /imu/data?)" in proc.stderr
    assert "--allow-missing" in proc.stderr
    assert not [p for p in tmp_path.iterdir() if p != config]  # refused before writing anything


def test_allow_missing_replays_without_it_and_says_so(jackal_bag, tmp_path):
    config = tmp_path / "typo.toml"
    config.write_text(CONFIG)
    tum = tmp_path / "out.tum"
    proc = fusiond("replay", str(jackal_bag), "--config", str(config), "--tum", str(tum), "--allow-missing",
                   "--advice-budget-s", "0")
    assert proc.returncode == 0, proc.stderr
    assert "topic /imu/dta is not in the bag (did you mean /imu/data?); replaying without it" in proc.stderr
    assert "missing     no bag topic for sensor(s): imu" in proc.stdout
    assert len(tum.read_text().splitlines()) == 3060


def test_a_silent_heading_reference_is_no_reference_to_the_doctor(tmp_path):
    """A differential pose configured but absent from the bag, replayed with --allow-missing: it delivered no
    heading, so the doctor still says the gyro's z bias was never learned on the Jackal bag (no standstill)."""
    config = tmp_path / "robot.toml"
    config.write_text(CONFIG.replace("imu/dta", "imu/data")
                      + '\n[[sensors]]\nname = "vo"\nkind = "pose"\nkey = "vo/odom"\ndifferential = true\n')
    proc = fusiond("doctor", str(ROOT / "data" / "jackal_test2.bag"), "--config", str(config), "--allow-missing")
    assert proc.returncode == 0, proc.stderr
    assert "was never learned" in proc.stdout
