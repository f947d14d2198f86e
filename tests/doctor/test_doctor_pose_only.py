"""An odometry driver that fills the pose only (robot_pose_ekf's input), the twist left zero: the doctor names
``twist_from_pose``, and the findings that read the robot's motion point at it. Simulated: the robot weaves for
60 s at 2 m/s (120 m of path, the check's metre a hundred times over), the drive's pose carrying the truth."""

from __future__ import annotations

import msgspec

from fusiond.core.sensors import OdomSample
from fusiond.estimator import rotation as rot

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import one, verdicts_of


def _samples(pose_only: bool) -> list:
    """The samples with each odometry message's pose the truth's; its twist zeroed when ``pose_only``."""
    cfg = SimConfig(duration=60.0, turn_amplitude=0.6, speed=2.0)
    samples = simulate(cfg)
    truth = {t: (x, y, h) for t, x, y, h in cfg.truth}
    out = []
    for s in samples:
        if type(s) is OdomSample:
            x, y, h = truth[s.stamp]
            s = msgspec.structs.replace(s, position=(x, y, 0.0), orientation=rot.from_rpy(0.0, 0.0, h))
            if pose_only:
                s = msgspec.structs.replace(s, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0))
        out.append(s)
    return out


def test_a_pose_only_driver_is_a_problem_naming_twist_from_pose():
    verdicts = verdicts_of(make_config(), _samples(pose_only=True))
    v = one(verdicts, "wheel", "twist")
    assert v.level == "problem" and v.key == "sensors.wheel.twist_from_pose", v
    assert v.suggestion == "twist_from_pose = true"
    assert v.evidence["pose_travel_m"] > 100.0 and v.evidence["twist_travel_m"] == 0.0, v.evidence
    others = [o for o in verdicts if o is not v and o.level != "ok"]
    assert others, "a robot taken as standing all run leaves no other finding: nothing to explain"
    for o in others:  # every other finding that is not ok reads the motion the filter never saw
        assert "explained by wheel/twist" in o.message and o.key == v.key and not o.suggestion, o


def test_with_twist_from_pose_or_a_twist_filled_nothing_is_said():
    derived = verdicts_of(make_config(extra_odom="twist_from_pose = true"), _samples(pose_only=True))
    assert not [v for v in derived if "twist_from_pose" in v.key], derived
    filled = verdicts_of(make_config(), _samples(pose_only=False))
    assert not [v for v in filled if "twist_from_pose" in v.key], filled
