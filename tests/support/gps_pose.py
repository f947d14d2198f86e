"""The GPS world and config of the GPS / pose tests."""

from __future__ import annotations

from tests.support.configs import robot_config
from tests.support.sim_gps import World

DATUM = "datum = [48.137, 11.575, 520.0]"


config = robot_config  # the builder these tests have always called


def _gps_world(**kw) -> World:
    base = dict(duration=120.0, start=(10.0, -5.0, 2.0), gps_rate=5.0, gps_sigma=0.3, wheel_scale=1.1,
                gyro_bias=0.003, gyro_scale=1.04, gps_lever=(0.3, 0.1, 0.5))
    base.update(kw)
    return World(**base)


def _gps_config(extra: str = ""):
    return config(gps=f"{DATUM}\nextrinsic_xyz = [0.3, 0.1, 0.5]\n{extra}", odom="scale_estimation = true",
                  imu="gyro_scale_estimation = true")
