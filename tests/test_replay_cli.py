"""End to end: `fusiond replay` as a user runs it, on the real Jackal bag; config errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from fusiond.config import load
from fusiond.replay.run import replay

ROOT = Path(__file__).resolve().parents[1]
RL_FINAL = (1.0206, 3.4292, 0.7419)  # robot_localization's EKF on this bag
RL_TOLERANCE = 0.1383


def fusiond(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiond", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)


@pytest.mark.e2e
def test_replay_like_robot_localization_lands_inside_its_tolerance(jackal_bag, tmp_path):
    tum = tmp_path / "rl.tum"
    diag = tmp_path / "rl.jsonl"
    png = tmp_path / "rl.png"
    proc = fusiond("replay", str(jackal_bag), "--config", "examples/jackal_rl.toml", "--tum", str(tum),
                   "--diagnostics", str(diag), "--plot", str(png))
    assert proc.returncode == 0, proc.stderr
    lines = tum.read_text().splitlines()
    assert len(lines) == 3060  # one per odometry message, none dropped
    last = lines[-1].split()
    assert len(last) == 8 and all(len(f.split(".")[1]) >= 9 for f in last)
    final = tuple(float(v) for v in last[1:4])
    assert math.dist(final, RL_FINAL) < RL_TOLERANCE
    stamps = [float(line.split()[0]) for line in lines]
    assert stamps == sorted(stamps)
    rec = json.loads(diag.read_text().splitlines()[10])
    assert {"stamp", "sensor", "components", "innovation", "innovation_var", "nis", "dof", "rejected"} <= rec.keys()
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "final pose" in proc.stdout and "NIS imu/orientation" in proc.stdout


@pytest.mark.e2e
def test_recommended_setup_tracks_the_imu_heading_with_the_gyro(jackal_bag):
    """Gyro-driven heading (roll/pitch from the IMU) follows the IMU's own yaw change over the run,
    while the skid-steer wheels' yaw rate is 2.3x too large and is flagged as slip."""
    from fusiond.estimator import rotation as rot

    cfg = load(ROOT / "examples/jackal.toml")
    res = replay([jackal_bag], cfg, progress=False)
    rl = replay([jackal_bag], load(ROOT / "examples/jackal_rl.toml"), progress=False)
    yaw_gyro = rot.to_rpy(tuple(res.core.pose()[1][3:7].tolist()))[2]
    yaw_imu = rot.to_rpy(tuple(rl.core.pose()[1][3:7].tolist()))[2]
    initial_imu_yaw = 0.3622  # the IMU's yaw at the first sample; the gyro run starts at 0
    assert rot.wrap(yaw_gyro - (yaw_imu - initial_imu_yaw)) == pytest.approx(0.0, abs=0.05)
    assert res.core.stats[0].dropped_total == 0 and res.core.stats[1].dropped_total == 0
    slip = res.core.consistency()["wheel/yaw_rate"]
    assert slip["rejected"] > 1000


@pytest.mark.e2e
def test_replay_with_arrival_order_scrambled_gives_the_same_answer(jackal_bag):
    """What the daemon sees over Zenoh (per-key delivery) must not change the estimate."""
    from fusiond.core.fusion import FusionCore
    from fusiond.replay.bag import open_bag_samples

    cfg = load(ROOT / "examples/jackal.toml")
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        samples = list(bag)
    a, b = FusionCore(cfg), FusionCore(cfg)
    for s in samples:
        a.ingest(s)
    odom = [s for s in samples if s.sensor == "wheel"]
    imu = [s for s in samples if s.sensor == "imu"]
    merged = []  # all odometry of each 0.1 s block before its IMU samples: worst case per-key delivery
    i = j = 0
    while i < len(odom) or j < len(imu):
        t_block = (odom[i].stamp if i < len(odom) else imu[j].stamp) + 0.1
        while i < len(odom) and odom[i].stamp < t_block:
            merged.append(odom[i])
            i += 1
        while j < len(imu) and imu[j].stamp < t_block:
            merged.append(imu[j])
            j += 1
    for s in merged:
        assert b.ingest(s).accepted
    assert a.pose()[1].tolist() == b.pose()[1].tolist()


@pytest.mark.parametrize("toml, needle", [
    ('[[sensors]]\nname="w"\nkind="odom"\nkey="odom"\nbogus=1\n', "sensors[0]: Object contains unknown field `bogus`"),
    ('[[sensors]]\nname="w"\nkind="lidar"\nkey="odom"\n', "sensors[0].kind: Invalid value 'lidar'"),
    ('[[sensors]]\nname="w"\nkind="odom"\nkey="odom"\n[[sensors]]\nname="i"\nkind="imu"\nkey="imu"\n'
     'orientation="sideways"\n', "sensors[1].orientation"),
    ('[filter]\nhistory_s="long"\n', "filter.history_s: Expected `float`, got `str`"),
    ('[zenoh]\nmode="mesh"\n', "zenoh.mode"),
    ('[[sensors]]\nname="i"\nkind="imu"\nkey="imu"\nextrinsic_rpy=[0.0, 1.0]\n', "sensors[0].extrinsic_rpy"),
    ('[[sensors]]\nname="w"\nkind="odom"\nkey="/odom"\n', "sensors[0].key"),
])
def test_bad_config_is_one_line_naming_the_key_and_exit_2(tmp_path, toml, needle):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(toml)
    proc = fusiond("replay", "nothing.bag", "--config", str(cfg))
    assert proc.returncode == 2
    assert needle in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_config_toml_at_the_root_documents_a_valid_config():
    cfg = load(ROOT / "config.toml")
    assert [s.name for s in cfg.sensors] == ["wheel", "imu"]
    text = (ROOT / "config.toml").read_text()
    for table in (cfg.zenoh, cfg.output, cfg.filter, *cfg.sensors):
        for field in table.__struct_fields__:
            assert f"{field} =" in text or f"{field}=" in text, f"config.toml does not document {field}"


def test_missing_bag_is_a_clear_error(tmp_path):
    proc = fusiond("replay", str(tmp_path / "nope.bag"), "--config", "examples/jackal.toml")
    assert proc.returncode == 2 and "nope.bag" in proc.stderr
