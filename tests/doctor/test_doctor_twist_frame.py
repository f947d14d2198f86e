"""The odometry twist in the frame the config says: a twist that points where the message's own pose heads is
the odom frame's, whatever the config calls it. Simulated: the robot weaves for 60 s (its heading sweeping
well past 0.3 rad), the drive's pose carrying its true heading."""

from __future__ import annotations

import math

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig
from tests.support.twist_frames import with_pose
from tests.support.verdicts import one, verdicts_of


def test_an_odom_frame_twist_configured_as_body_is_a_problem_naming_world():
    cfg = SimConfig(duration=60.0, turn_amplitude=0.6, speed=2.0)
    v = one(verdicts_of(make_config(), with_pose(cfg, world=True)), "wheel", "twist")
    assert v.level == "problem" and v.suggestion == 'twist_frame = "world"', v
    body = [v for v in verdicts_of(make_config(), with_pose(SimConfig(duration=60.0, turn_amplitude=0.6, speed=2.0),
                                                             world=False)) if v.channel == "twist"]
    assert body == [], body


def test_a_world_twist_without_a_pose_beside_a_gps_is_named_and_the_body_frame_pasted():
    """A car with a GPS whose drive fills no pose (identity orientation), configured with twist_frame = "world":
    the twist cannot be turned into the body, so it is taken in the GPS's ENU as it stands (the car 'drives'
    east whatever its heading). On gentle curves neither other rule fires (no turned pose, little yaw rate):
    named from the missing pose; pasted, the body frame is nothing to say and the track follows the truth."""
    from fusiond.core.fusion import FusionCore

    from tests.support import sim_gps
    from tests.support.configs import robot_config

    w = sim_gps.World(duration=60.0, speed=10.0, gps_rate=5.0, gps_sigma=0.5, start=(0.0, 0.0, 1.2),
                      arcs=((10.0, 60.0, 0.01),))
    samples = sim_gps.simulate(w)
    v = one(verdicts_of(robot_config(gps="", odom='twist_frame = "world"'), samples), "wheel", "twist")
    assert v.level == "problem" and v.key == "sensors.wheel.twist_frame" and v.suggestion == 'twist_frame = "body"', v
    fixed = robot_config(gps="", odom=v.suggestion)
    assert not [x for x in verdicts_of(fixed, samples) if x.channel == "twist" and x.level != "ok"]
    core = FusionCore(fixed)
    for s in samples:
        core.ingest(s)
    t, x = core.pose()
    truth = min(w.truth, key=lambda p: abs(p[0] - t))
    assert math.hypot(x[0] - truth[1], x[1] - truth[2]) < 3.0
