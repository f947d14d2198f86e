"""REP-105's continuous odom frame by default: with odometry + an IMU's roll/pitch + the gyro (README step 1,
every other key at its default), consecutive poses `fusiond replay` publishes never step by more than the
odometry's motion allows plus 5 cm, also when a standstill teaches the filter its gyro bias.

The F1/10 recording in ../shared/data stops (and reads false standstills) after 60 s of driving on a biased
gyro: there the correlated bias correction used to move the published pose by 9.5 m in one 0.04 s step, as
`continuous_odom = false` still does (the control below shows the recording exercises it). Skipped without
the recordings; the Jackal bag (no standstill) always runs.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from fusiond.config import load
from tests.support.odom_steps import excess_steps, odom_speeds, read_tum

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
F110 = DATA / "f110_ds2"

pytestmark = pytest.mark.e2e

STEP1 = """{filt}
[[sensors]]
name = "wheel"
kind = "odom"
key = "{odom}"
twist_frame = "body"

[[sensors]]
name = "imu"
kind = "imu"
key = "{imu}"
orientation = "roll_pitch"
angular_velocity = true
extrinsic_rpy = [0.0, 0.0, 0.0]
"""


def _replay_steps(bag: Path, tmp_path: Path, odom: str, imu: str, filt: str = "") -> tuple[list, str]:
    """(the steps above the bound, replay's stdout) of README step 1's config on ``bag``."""
    config = tmp_path / "step1.toml"
    config.write_text(STEP1.format(filt=filt, odom=odom, imu=imu))
    tum = tmp_path / "step1.tum"
    proc = subprocess.run([sys.executable, "-m", "fusiond", "replay", str(bag), "--config", str(config),
                           "--tum", str(tum), "--advice-budget-s", "0"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    track = read_tum(tum)
    assert len(track) > 100
    return excess_steps(track, odom_speeds([bag], load(config))), proc.stdout


@pytest.mark.parametrize("name", ["f110_ds2", "comma2k19_ex1"])
def test_the_shared_recordings_with_step_1_keep_their_odom_frame_continuous(name, tmp_path):
    if not (DATA / name).exists():
        pytest.skip(f"the recording is not in {DATA / name} (see docs/RESULTS.md)")
    steps, _ = _replay_steps(DATA / name, tmp_path, "odom", "imu")
    assert not steps, steps[:5]


@pytest.mark.skipif(not F110.exists(), reason=f"the F1/10 recording is not in {F110} (see docs/RESULTS.md)")
def test_a_gyro_bias_learned_at_a_standstill_never_steps_the_published_pose(tmp_path):
    steps, out = _replay_steps(F110, tmp_path, "odom", "imu")
    assert not steps, steps[:5]
    bias_z = float(next(l for l in out.splitlines() if l.startswith("gyro bias")).split("[")[1].split(",")[2]
                   .rstrip("] rad/s"))
    assert abs(bias_z) > 1e-3  # the standstills did teach the z bias that turned the pose before


@pytest.mark.skipif(not F110.exists(), reason=f"the F1/10 recording is not in {F110} (see docs/RESULTS.md)")
def test_the_control_the_jumping_correction_is_still_there_when_asked_for(tmp_path):
    steps, _ = _replay_steps(F110, tmp_path, "odom", "imu", filt="[filter]\ncontinuous_odom = false")
    assert steps and max(s[1] - s[2] for s in steps) > 1.0  # metres in one step: what the default prevents


def test_the_jackal_bag_with_step_1_keeps_its_odom_frame_continuous(jackal_bag, tmp_path):
    steps, _ = _replay_steps(jackal_bag, tmp_path, "jackal_velocity_controller/odom", "imu/data")
    assert not steps, steps[:5]


@pytest.mark.skipif(not F110.exists(), reason=f"the F1/10 recording is not in {F110} (see docs/RESULTS.md)")
def test_the_daemon_fed_the_recording_publishes_the_same_continuous_odom_frame(tmp_path):
    """`fusiond play` of the F1/10 recording into `fusiond run` (README step 1, loopback Zenoh): the poses on
    odom_combined keep the same bound as replay's."""
    from fusiond.codecs import decode_pose_cdr
    from tests.support.daemon import (
        client_session, daemon_process, free_port, fusiond_cmd, health, wait_daemon_ready, wait_until,
    )

    port = free_port()
    config = tmp_path / "step1.toml"
    config.write_text(f'[zenoh]\nmode = "peer"\nlisten = ["tcp/127.0.0.1:{port}"]\nmulticast_scouting = false\n'
                      + STEP1.format(filt="", odom="odom", imu="imu"))
    log = tmp_path / "daemon.log"
    poses: list[tuple[float, tuple[float, float, float]]] = []

    def on_pose(sample) -> None:
        msg = decode_pose_cdr(sample.payload.to_bytes())
        p = msg.pose.pose.position
        poses.append((msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, (p.x, p.y, p.z)))

    with daemon_process(config, log) as proc, client_session(port) as session:
        session.declare_subscriber("odom_combined", on_pose)
        wait_daemon_ready(session, proc, log)
        play = subprocess.run(fusiond_cmd("play", str(F110), "--config", str(config), "--rate", "10", "--connect",
                                          f"tcp/127.0.0.1:{port}"), capture_output=True, text=True, timeout=300,
                              cwd=ROOT)
        assert play.returncode == 0, play.stderr  # everything sent was fused
        wait_until(lambda: (h := health(session)) and h["published"] == len(poses) > 1000, 20, "every pose")
    steps = excess_steps(poses, odom_speeds([F110], load(config)))
    assert not steps, steps[:5]
