"""`fusiond init BAG --out FILE` and `fusiond info BAG` through the real CLI, on the Jackal bag and the shared
recordings: the config written is one `replay` accepts with every sensor the bag offers (never its
`/ground_truth`), each choice commented; the mounts come from `/tf_static`.

On the Jackal bag init chooses, as the README recommends, roll/pitch from the IMU and the gyro for heading
(the IMU's yaw is not fused: the bag cannot say whether its magnetometer is trustworthy). That config starts
at heading 0, where robot_localization's (the IMU's absolute yaw) starts at the IMU's first yaw; turned by
that yaw about the start, its final pose lies within robot_localization's tolerance of its final pose.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from fusiond.bag_info import BagInfo, StaticTransform, TopicInfo
from fusiond.config import load
from fusiond.estimator import rotation as rot
from fusiond.init_config import generate_config, mount
from fusiond.replay.bag import open_bag_samples

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
RL_FINAL = (1.0206, 3.4292, 0.7419)
RL_TOLERANCE = 0.1383

pytestmark = pytest.mark.e2e


def fusiond(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiond", *args], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)


def _applied(summary: str) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^sensor (\w+)\s+received=\d+ applied=(\d+)",
                                                             summary, re.M)}


def test_init_on_the_jackal_bag_writes_a_config_replay_accepts_and_lands_within_the_tolerance(jackal_bag, tmp_path):
    out = tmp_path / "robot.toml"
    proc = fusiond("init", str(jackal_bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "doctor " in proc.stdout and "final pose" in proc.stdout  # init replayed it once with the doctor
    cfg = load(out)
    assert {s.name: s.key for s in cfg.sensors} == {"wheel": "jackal_velocity_controller/odom", "imu": "imu/data"}
    text = out.read_text()
    for key in ("kind", "twist_frame", "orientation", "angular_velocity", "extrinsic_rpy"):
        line = next(ln for ln in text.splitlines() if ln.startswith(key))
        assert "#" in line, line  # every choice says why
    tum = tmp_path / "robot.tum"
    proc = fusiond("replay", str(jackal_bag), "--config", str(out), "--tum", str(tum), "--advice-budget-s", "0")
    assert proc.returncode == 0, proc.stderr
    assert _applied(proc.stdout) == {"wheel": 3060, "imu": 3061}
    rows = [[float(v) for v in line.split()] for line in tum.read_text().splitlines()]
    with open_bag_samples([jackal_bag], [s for s in cfg.sensors if s.name == "imu"]) as bag:
        first_yaw = rot.yaw(next(iter(bag)).orientation)
    x0, y0 = rows[0][1:3]
    dx, dy = rows[-1][1] - x0, rows[-1][2] - y0
    c, s = math.cos(first_yaw), math.sin(first_yaw)
    turned = (x0 + c * dx - s * dy, y0 + s * dx + c * dy, rows[-1][3])
    assert math.dist(turned, RL_FINAL) < RL_TOLERANCE, turned


@pytest.mark.parametrize("name, sensors", [("comma2k19_ex1", {"wheel": "odom", "imu": "imu", "gps": "fix"}),
                                           ("f110_ds2", {"wheel": "odom", "imu": "imu"})])
def test_init_on_each_shared_recording_fuses_every_sensor_it_offers_and_never_its_reference(name, sensors, tmp_path):
    bag = DATA / name
    if not bag.exists():
        pytest.skip(f"the recording is not in {bag} (see docs/RESULTS.md)")
    out = tmp_path / f"{name}.toml"
    proc = fusiond("init", str(bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    # its replay is `fusiond replay`'s: every paste line the doctor prints was replayed
    pasted = [line for line in proc.stdout.splitlines() if line.lstrip().startswith(("->", "tried in"))]
    assert pasted and all("not replayed" not in line for line in proc.stdout.splitlines()), proc.stdout
    assert proc.stdout.count("likelihood") + proc.stdout.count("changes none") >= len(pasted), proc.stdout
    cfg = load(out)
    assert {s.name: s.key for s in cfg.sensors} == sensors
    assert "/ground_truth" in out.read_text() and all("ground_truth" not in s.key for s in cfg.sensors)
    proc = fusiond("replay", str(bag), "--config", str(out), "--advice-budget-s", "0")
    assert proc.returncode == 0, proc.stderr
    applied = _applied(proc.stdout)
    assert set(applied) == set(sensors) and all(n > 100 for n in applied.values()), proc.stdout


def test_an_imu_stating_zero_covariances_is_said_to_be_floored():
    """An IMU whose every gyro and orientation variance is 0: each is floored at its table's *_min_sigma, and the
    config says so with the key to state; an IMU stating its noise gets no such line."""
    info = _info()
    imu = next(t for t in info.topics if t.msgtype == "sensor_msgs/msg/Imu")
    assert "covariance is 0" not in generate_config(info, ["x"])
    imu.gyro_zero_covariance = imu.orientation_zero_covariance = True
    text = generate_config(info, ["x"])
    assert "# every gyro covariance is 0: floored at gyro_min_sigma (0.0005 rad/s)" in text and "gyro_noise" in text
    assert "# every orientation covariance is 0: floored at orientation_min_sigma (0.001 rad)" in text, text
    tomllib.loads(text)


def test_the_config_says_how_an_operator_reaches_the_robot():
    """The listen endpoint an operator's monitor dials where multicast does not pass, commented out (the
    defaults stand until a user asks), so that uncommenting it gives a config the loader accepts."""
    text = generate_config(_info(), ["x"])
    assert "# [zenoh]" in text and '# listen = ["tcp/0.0.0.0:7447"]' in text and "fusiond monitor --connect" in text
    assert "zenoh" not in tomllib.loads(text)
    opened = text.replace("# [zenoh]", "[zenoh]").replace('# listen = ["tcp/0.0.0.0:7447"]', 'listen = ["tcp/0.0.0.0:7447"]')
    assert tomllib.loads(opened)["zenoh"]["listen"] == ["tcp/0.0.0.0:7447"]
    from fusiond.config import loads

    assert loads(opened).zenoh.listen == ["tcp/0.0.0.0:7447"]


def test_the_recordings_own_traits_are_read(tmp_path):
    """comma2k19's IMU publishes no orientation (covariance[0] = -1): orientation off; the F1/10 driver lost its
    yaw rate (exactly 0 while driving) and states zero covariances: twist_measured says so, and the IMU's zero
    covariances are said to be floored."""
    for name, expect in (("comma2k19_ex1", ('orientation = "off"',)),
                         ("f110_ds2", ("twist_measured = [true, true, true, false, false, false]",
                                       "# every gyro covariance is 0"))):
        bag = DATA / name
        if not bag.exists():
            pytest.skip(f"the recording is not in {bag} (see docs/RESULTS.md)")
        out = tmp_path / f"{name}.toml"
        assert fusiond("init", str(bag), "--out", str(out)).returncode == 0
        assert all(any(line.startswith(e) for line in out.read_text().splitlines()) for e in expect), out.read_text()


def test_init_refuses_to_overwrite_without_force(jackal_bag, tmp_path):
    out = tmp_path / "robot.toml"
    out.write_text("# mine\n")
    proc = fusiond("init", str(jackal_bag), "--out", str(out))
    assert proc.returncode == 2 and "--force" in proc.stderr and out.read_text() == "# mine\n"


def test_info_lists_topics_types_counts_rates_covariances_and_use(jackal_bag):
    proc = fusiond("info", str(jackal_bag))
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "/imu/data  sensor_msgs/msg/Imu  3061 msgs  50.0 Hz frame base_link" in out
    assert "/jackal_velocity_controller/odom  nav_msgs/msg/Odometry  3060 msgs  50.0 Hz frame odom -> base_link" in out
    assert "stated: orientation sigma [0.00051, 0.00051, 0.005] rad, gyro sigma [0.005, 0.005, 0.005] rad/s" in out
    assert "use:    odom sensor: its twist drives the prediction" in out
    assert fusiond("info", str(ROOT / "README.md")).returncode == 2


# -- the choices the shipped recordings do not exercise, from a recording's facts -----------------------------

def _info(static=(), imu_frame="imu_link", lateral=(0.0, 0.0), gps=True) -> BagInfo:
    topics = [TopicInfo(topic="/odom", msgtype="nav_msgs/msg/Odometry", count=500, rate_hz=50.0, frame_id="odom",
                        child_frame_id="base_link", lateral_body=lateral[0], lateral_rotated=lateral[1],
                        yaw_rate_zero=False, twist_zero_covariance=False),
              TopicInfo(topic="/imu/data", msgtype="sensor_msgs/msg/Imu", count=1000, rate_hz=100.0,
                        frame_id=imu_frame, orientation_valid=True, gyro_measured=True)]
    if gps:
        topics.append(TopicInfo(topic="/gps/fix", msgtype="sensor_msgs/msg/NavSatFix", count=50, rate_hz=5.0,
                                frame_id="gps_link", covariance_type=2))
    topics.append(TopicInfo(topic="/ground_truth", msgtype="geometry_msgs/msg/PoseStamped", count=10, rate_hz=1.0))
    return BagInfo(paths=["x"], ros2=True, duration_s=10.0, topics=topics, static=list(static))


def test_the_imu_mount_and_the_antenna_come_from_tf_static_along_a_chain():
    """base_link -> plate (0.1 m forward, yawed 90 deg) -> imu_link (rolled 180 deg: mounted upside down), given
    partly child -> parent; the antenna 0.5 m behind and 1 m above base_link."""
    yaw90 = rot.from_rpy(0.0, 0.0, math.pi / 2)
    static = [StaticTransform("base_link", "plate", (0.1, 0.0, 0.0), yaw90),
              StaticTransform("imu_link", "plate", (0.0, 0.0, 0.0), rot.conj(rot.from_rpy(math.pi, 0.0, 0.0))),
              StaticTransform("base_link", "gps_link", (-0.5, 0.0, 1.0), rot.IDENTITY)]
    p, q = mount(static, "base_link", "imu_link")
    want = rot.mul(yaw90, rot.from_rpy(math.pi, 0.0, 0.0))
    assert p == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
    assert abs(sum(a * b for a, b in zip(q, want))) == pytest.approx(1.0, abs=1e-12)
    text = generate_config(_info(static), ["x"])
    cfg = tomllib.loads(text)
    imu = next(s for s in cfg["sensors"] if s["kind"] == "imu")
    r = rot.from_rpy(*imu["extrinsic_rpy"])
    assert abs(sum(a * b for a, b in zip(r, want))) == pytest.approx(1.0, abs=1e-5)
    gps = next(s for s in cfg["sensors"] if s["kind"] == "gps")
    assert gps["extrinsic_xyz"] == [-0.5, 0.0, 1.0]
    assert all(s["key"] != "ground_truth" for s in cfg["sensors"])


def test_an_imu_frame_without_a_transform_is_taken_as_identity_and_said_so():
    text = generate_config(_info(gps=False), ["x"])
    assert "no /tf_static from base_link to 'imu_link'" in text and "# To check:" in text


def test_a_twist_stated_in_the_odometry_frame_is_read_as_world():
    """Sideways while driving as stated (80 % of the speed), not once turned by the message's heading (2 %)."""
    world = tomllib.loads(generate_config(_info(lateral=(0.8, 0.02), gps=False), ["x"]))
    body = tomllib.loads(generate_config(_info(lateral=(0.0, 0.8), gps=False), ["x"]))
    assert world["sensors"][0]["twist_frame"] == "world" and body["sensors"][0]["twist_frame"] == "body"
