"""`replay --reference`: the scorer, checked where the answer is known.

A simulated drive with a known truth is written as a real ROS 2 bag (the real codec) with the truth on
/ground_truth; the CLI scores it. The thresholds come from the simulation: white fixes of std dev sigma
per axis have a horizontal RMS error of sqrt(2) sigma, whose estimate over n fixes spreads by about
1/sqrt(2n) of itself (a chi-square with 2n dof); a held fix k periods old at speed v is v k / rate off.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fusiond.cli import main
from fusiond.estimator import rotation as rot
from fusiond.replay.evaluate import Track, _aligned_rms
from fusiond.core.sensors.pose import PoseSample
from fusiond.core.sensors import GpsSample, ImuSample, OdomSample
from tests.support.configs import robot_config_text
from tests.support.ros2_bags import write_ros2_bag
from tests.support.sim_gps import World, simulate

TYPES = {OdomSample: "nav_msgs/msg/Odometry", ImuSample: "sensor_msgs/msg/Imu",
         GpsSample: "sensor_msgs/msg/NavSatFix", PoseSample: "geometry_msgs/msg/PoseStamped"}
TOPICS = {"wheel": "/odom", "imu": "/imu", "gps": "/gps", "truth": "/ground_truth"}



def _write_bag(path: Path, w: World) -> None:
    samples = simulate(w)
    # the reference in the filter's world frame: ENU at the first fix (its datum), as a real reference
    # recorded in ENU at the receiver's first fix is
    _, e0, n0 = w.fixes[0]
    truth = [PoseSample("truth", t, (x - e0, y - n0, 0.0), rot.from_rpy(0.0, 0.0, h)) for t, x, y, h in w.truth]
    write_ros2_bag(path, sorted(samples + truth, key=lambda s: s.stamp), TOPICS, TYPES)


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> tuple[Path, Path, World]:
    root = tmp_path_factory.mktemp("evaluate")
    w = World(duration=40.0, gps_rate=5.0, gps_sigma=0.5, speed=2.0, seed=3)
    _write_bag(root / "bag", w)
    cfg = root / "robot.toml"
    cfg.write_text(robot_config_text(gps=""))
    return root / "bag", cfg, w


def _scores(out: Path) -> dict[str, dict]:
    ev = json.loads(out.read_text())
    return {s["method"]: s for s in ev["scores"] if s["segment"] == "all"}


def test_raw_fixes_score_their_simulated_noise(drive, tmp_path: Path, capsys) -> None:
    bag, cfg, w = drive
    out = tmp_path / "ev.json"
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/ground_truth", "--quiet",
                 "--evaluation", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "raw fixes" in printed and "gyro + wheel speed" in printed
    s = _scores(out)
    raw = s["raw fixes"]
    n_fixes = len(w.fixes)
    expected = math.sqrt(2.0) * w.gps_sigma
    # fixes interpolated to the 20 Hz reference stamps average neighbours: the RMS can only drop (to
    # sqrt(1/2) at the midpoints), never rise; the estimate's own spread is 1/sqrt(2 n) of it
    spread = 3.0 / math.sqrt(2.0 * n_fixes)
    assert math.sqrt(0.5) * expected * (1 - spread) <= raw["world_h"] <= expected * (1 + spread)
    # the fused estimate and every dead-reckoned baseline are scored; the drive is planar (truth z = 0)
    assert s["fusiond"]["world_h"] is not None and s["wheel odometry"]["world_h"] is None
    assert s["wheel odometry"]["aligned_h"] is not None


def test_held_back_fixes_score_the_hold_and_the_gps_noise(drive, tmp_path: Path) -> None:
    bag, cfg, w = drive
    out = tmp_path / "ev.json"
    every = 5
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/ground_truth", "--fuse-every",
                 str(every), "--quiet", "--evaluation", str(out)]) == 0
    ev = json.loads(out.read_text())
    s = _scores(out)
    held = len(w.fixes) - len(w.fixes[::every])
    assert ev["fuse_every"] == every and s["raw fixes"]["n"] <= held
    assert "fusiond smoothed" not in s and "fused fixes interpolated" not in s  # only with --smooth
    # the raw held-back fixes, scored at their own stamps against the truth: their noise, sqrt(2) sigma
    n = s["raw fixes"]["n"]
    expected = math.sqrt(2.0) * w.gps_sigma
    assert abs(s["raw fixes"]["world_h"] - expected) <= expected * 3.0 / math.sqrt(2.0 * n)
    # a fix held k periods (k = 1..every-1) at speed v is v k / rate behind, beside its own noise
    k = np.arange(1, every)
    lag = w.speed / w.gps_rate * math.sqrt(np.mean(k**2))
    hold = math.sqrt(lag**2 + expected**2)
    assert abs(s["hold last fused fix"]["world_h"] - hold) <= 0.25 * hold


def test_smooth_scores_the_smoothed_track_beside_the_filter_and_the_fused_fixes_interpolated(drive, tmp_path):
    """With --smooth and thinned fixes: a smoothed row, closer to the truth than the filter on the held-back
    fixes' stamps, and the non-causal baseline it competes with (and beats). The fused fixes interpolated
    carry the fixes' white noise, sqrt(2) sigma horizontally at a fix, less between two (an average of two independent
    errors), and the chord of the drive's weave between fixes one second apart."""
    bag, cfg, w = drive
    out = tmp_path / "ev.json"
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/ground_truth", "--fuse-every", "5",
                 "--smooth", "--quiet", "--evaluation", str(out)]) == 0
    s = _scores(out)
    assert s["fusiond smoothed"]["n"] == s["fusiond"]["n"] > 0
    assert s["fusiond smoothed"]["world_h"] < s["fusiond"]["world_h"]
    interp = s["fused fixes interpolated"]["world_h"]
    assert 0.5 * w.gps_sigma < interp < 3.0 * w.gps_sigma
    # the odometry between the fixes knows the shape of the drive, a straight line between them does not
    assert s["fusiond smoothed"]["world_h"] < interp


def test_the_absolute_sensor_itself_is_the_reference_of_its_held_back_messages(drive, tmp_path: Path) -> None:
    bag, cfg, _ = drive
    out = tmp_path / "ev.json"
    assert main(["replay", str(bag), "--config", str(cfg), "--fuse-every", "4", "--quiet",
                 "--evaluation", str(out)]) == 0
    s = _scores(out)
    assert s["raw fixes"]["world_h"] == 0.0  # scored against themselves
    assert s["fusiond"]["n"] > 0


@pytest.mark.e2e
def test_the_report_shows_the_evaluation(drive, tmp_path: Path) -> None:
    bag, cfg, _ = drive
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/ground_truth", "--quiet",
                 "--report", str(tmp_path / "report")]) == 0
    page = (tmp_path / "report" / "index.html").read_text()
    assert '<pre id="evaluation">' in page and "gyro + wheel speed" in page


def test_a_fused_topic_is_refused_as_reference(drive, capsys) -> None:
    bag, cfg, _ = drive
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/odom", "--quiet"]) == 2
    assert "never be fused" in capsys.readouterr().err


def test_alignment_removes_a_rigid_motion_and_only_that() -> None:
    rng = np.random.default_rng(0)
    ref = np.cumsum(rng.normal(0, 1, (200, 2)), axis=0)
    a = 0.7
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    est = (r @ ref.T).T + (5.0, -3.0)
    assert _aligned_rms(est, ref) < 1e-9
    noise = rng.normal(0, 0.1, ref.shape)
    assert abs(_aligned_rms(est + noise, ref) - math.sqrt(2) * 0.1) < 0.02
    parked = np.zeros((10, 2))  # nothing to fit a rotation to: aligned by the mean
    assert _aligned_rms(parked, parked + (1.0, 2.0)) < 1e-12


def test_tracks_interpolate_within_their_gaps_and_hold_a_step() -> None:
    t = np.array([0.0, 1.0, 2.0, 10.0])
    xyz = np.column_stack((t, np.zeros(4), np.zeros(4)))
    track = Track.build("x", t, xyz, heading=np.array([3.1, -3.1, -3.0, -3.0]))
    p, h, ok = track.at(np.array([0.5, 1.5, 5.0, 10.0, 11.0]), max_gap=1.0)
    assert ok.tolist() == [True, True, False, True, False]
    assert p[0, 0] == 0.5 and p[1, 0] == 1.5
    assert abs(h[0] - (3.1 + (2 * math.pi - 6.2) / 2)) < 1e-12  # across +-pi the short way round
    held = Track.build("h", t, xyz, held=True)
    p, _, ok = held.at(np.array([-1.0, 1.5, 5.0]), max_gap=1.0)
    assert ok.tolist() == [False, True, True] and p[1, 0] == 1.0 and p[2, 0] == 2.0


def test_poses_published_before_the_heading_is_known_are_not_scored_on_heading(tmp_path: Path) -> None:
    """The robot starts facing north; the filter publishes yaw 0 with an "unknown" yaw variance until the
    fixes span the travel a heading fit needs. Those placeholder yaws, 90 deg off, would dominate the RMS
    (at least 90 sqrt(k / n) deg for k of n poses); they are left out of the heading and RPE, the note
    says how many, and what remains is the filter's real heading error (well under 10 deg)."""
    from fusiond.config import loads
    from fusiond.core.fusion import FusionCore

    w = World(duration=30.0, gps_rate=5.0, gps_sigma=0.5, speed=2.0, start=(0.0, 0.0, math.pi / 2), seed=4)
    _write_bag(tmp_path / "bag", w)
    cfg = tmp_path / "robot.toml"
    cfg.write_text(robot_config_text(gps=""))
    core = FusionCore(loads(cfg.read_text()))
    unknown = total = 0
    for s in simulate(World(duration=30.0, gps_rate=5.0, gps_sigma=0.5, speed=2.0, start=(0.0, 0.0, math.pi / 2),
                            seed=4)):
        if core.ingest(s).publish:
            total += 1
            unknown += not core.heading_known
    assert unknown >= 0.1 * total  # the trait: a tenth of the run waits for its heading
    out = tmp_path / "ev.json"
    assert main(["replay", str(tmp_path / "bag"), "--config", str(cfg), "--reference", "/ground_truth", "--quiet",
                 "--evaluation", str(out)]) == 0
    ev = json.loads(out.read_text())
    assert any(f"skip the {unknown} poses published before its heading was known" in n for n in ev["notes"]), ev["notes"]
    assert _scores(out)["fusiond"]["heading_deg"] < 10.0


def test_a_track_reads_no_heading_where_it_was_not_known() -> None:
    tr = Track.build("t", [0.0, 1.0, 2.0, 3.0], np.zeros((4, 3)), [0.0, 0.0, 1.0, 1.0], heading_known=[0, 0, 1, 1])
    _, h, valid = tr.at(np.array([0.5, 1.5, 2.5]), 5.0)
    assert valid.all() and np.isnan(h[0]) and np.isnan(h[1]) and h[2] == pytest.approx(1.0)


def test_a_world_error_that_is_one_constant_offset_says_so(drive, tmp_path: Path) -> None:
    """The GPS's datum set 100 m south of the first fix: the filter's world origin is 100 m from the
    reference's, and its world error is that offset (the track itself is as good: aligned the same). The
    evaluation says the world error is mostly one constant offset, and gives it (the positions 100 m north of
    the reference's, within the fixes' noise); with the datum at the first fix nothing is said."""
    bag, cfg, w = drive
    _, e0, n0 = w.fixes[0]
    lat0, lon0, alt0 = w.datum
    # the first fix's own geodetic position, then 100 m south of it (a small-angle step on the sphere)
    from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic

    first = enu_to_geodetic(EnuFrame(lat0, lon0, alt0), e0, n0, 0.0)
    south = (first[0] - math.degrees(100.0 / 6378137.0), first[1], first[2])
    moved = tmp_path / "moved.toml"
    moved.write_text(robot_config_text(gps=f"datum = [{south[0]!r}, {south[1]!r}, {south[2]!r}]"))
    notes = {}
    for name, config in (("moved", moved), ("first fix", cfg)):
        out = tmp_path / f"{name}.json"
        assert main(["replay", str(bag), "--config", str(config), "--reference", "/ground_truth", "--quiet",
                     "--evaluation", str(out)]) == 0
        notes[name] = [n for n in json.loads(out.read_text())["notes"] if "constant offset" in n]
        if name == "moved":
            offset = _scores(out)["fusiond"]["world_offset"]
            assert abs(offset[1] - 100.0) < 2.0 and abs(offset[0]) < 2.0, offset
    assert len(notes["moved"]) == 1 and "datum" in notes["moved"][0]
    assert notes["first fix"] == []


def test_a_mistyped_reference_is_refused_before_the_recording_is_fused(drive, tmp_path: Path, capsys) -> None:
    """Exit 2 naming the topic it may have meant, and nothing fused: the TUM file the replay would write is
    not written."""
    bag, cfg, _ = drive
    tum = tmp_path / "never.tum"
    assert main(["replay", str(bag), "--config", str(cfg), "--reference", "/ground_trut", "--tum", str(tum)]) == 2
    err = capsys.readouterr().err
    assert "--reference /ground_trut: no such topic" in err and "did you mean /ground_truth?" in err, err
    assert not tum.exists()


def test_a_smoothed_poses_heading_is_looked_up_in_its_own_timeline_after_a_clock_reset():
    """The smoothed track has the published one's moments, a clock reset included: each smoothed pose's heading
    counts as known where the published pose of the same run between jumps back was (the run after a jump back
    lies earlier in time: looked up across both, a stamp finds the other run's poses, still searching for their
    heading, and the smoothed heading's score reads 14 deg where the filter's reads 0.1)."""
    from fusiond.replay.evaluate import _known_by_then

    published = np.array([100.0, 101.0, 102.0, 103.0, 10.0, 11.0, 12.0, 13.0])
    known = np.array([False, True, True, True, False, False, True, True])
    assert _known_by_then(published, known, published).tolist() == known.tolist()
    # a smoothed track with a pose more in the second run (a late sample's moment): still its own run's
    smoothed = np.array([100.0, 101.5, 103.0, 10.0, 10.5, 12.5])
    assert _known_by_then(published, known, smoothed).tolist() == [False, True, True, False, False, True]
