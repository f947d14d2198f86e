"""Simulated drives whose odometry carries the truth's heading as its pose, the twist in the body or the odom frame."""

from __future__ import annotations

import math

import msgspec

from fusiond.core.sensors import OdomSample
from fusiond.estimator import rotation as rot

from tests.support.sim import SimConfig, simulate


def with_pose(cfg: SimConfig, world: bool) -> list:
    """The samples with each odometry message's pose heading the truth's, and its twist turned into the odom
    frame by that heading when ``world``."""
    samples = simulate(cfg)
    yaw = {t: h for t, _, _, h in cfg.truth}
    out = []
    for s in samples:
        if type(s) is OdomSample:
            h = yaw[s.stamp]
            vx, vy, vz = s.linear
            linear = (vx * math.cos(h) - vy * math.sin(h), vx * math.sin(h) + vy * math.cos(h), vz) if world else s.linear
            s = msgspec.structs.replace(s, linear=linear, orientation=rot.from_rpy(0.0, 0.0, h))
        out.append(s)
    return out
