"""The doctor's fit of a visual odometry camera's mount yaw against the wheels' direction of motion
(fusiond/doctor/pose_motion.py, checks/pose_mount.py).

A wheeled base moves along its own x: a camera's deltas, read in base_link's axes through extrinsic_rpy, lean
sideways by the mount yaw that extrinsic_rpy leaves out. On the highway car a camera 0.9 deg off read "consistent"
while it made the estimate four times worse; its fitted line, pasted, brought it below the gyro's."""

from __future__ import annotations

import math

import pytest

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.verdicts import vector, verdicts_of

MOUNT = 0.3  # rad: the camera turned 17 deg to the left of base_link's forward


def _vo(mount: float):
    """A camera's visual odometry at 10 Hz beside the wheels (its poses' noise white: the simulation's accumulating
    one drifts the yaw while the positions do not, which no camera does, and which turns every delta by it)."""
    w = sim_gps.World(duration=60.0, start=(0.0, 0.0, 0.0), speed=2.0, pose_rate=10.0, pose_mount_yaw=mount,
                      pose_sigma=(0.005, 0.002), arcs=((10.0, 20.0, 0.2), (30.0, 40.0, -0.2)))
    return sim_gps.simulate(w)


@pytest.mark.parametrize("stated", [0.0, MOUNT], ids=["unstated", "stated"])
def test_a_camera_turned_in_its_mount_is_named_with_its_yaw(stated):
    """Unstated, the doctor names extrinsic_rpy with the mount's yaw (within 3 of its standard errors); stated, it
    says nothing of the mount."""
    cfg = robot_config(pose=f"differential = true\nextrinsic_rpy = [0.0, 0.0, {stated}]")
    mount = [v for v in verdicts_of(cfg, _vo(MOUNT)) if v.sensor == "pose" and v.channel == "mount"]
    if stated:
        assert not mount, mount
        return
    assert len(mount) == 1 and mount[0].key == "sensors.pose.extrinsic_rpy", mount
    v = mount[0]
    yaw, se = v.evidence["mount_yaw_error_rad"], v.evidence["mount_yaw_se"]
    assert abs(yaw - MOUNT) < 3 * se and se < 0.01, v.evidence
    assert math.isclose(vector(v.suggestion)[2], yaw, abs_tol=1e-4), v.suggestion


def test_an_aligned_camera_is_not_named():
    mount = [v for v in verdicts_of(robot_config(pose="differential = true"), _vo(0.0))
             if v.sensor == "pose" and v.channel == "mount"]
    assert not mount, mount
