"""Core input samples and the robot config the fusion-core tests build on."""

from __future__ import annotations

from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config


def make_config(orientation: str = "roll_pitch", gyro: bool = True, extra_imu: str = "", extra_filter: str = "",
                extra_odom: str = ""):
    """``robot_config`` with the IMU on key "imu/data", as the core tests have always used it."""
    return robot_config(odom=extra_odom, imu=extra_imu, filt=extra_filter, orientation=orientation, gyro=gyro,
                        imu_key="imu/data")


def odom(t, v=0.0, w=0.0, var=1e-4, sensor="wheel"):
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = var
    return OdomSample(sensor, t, (v, 0.0, 0.0), (0.0, 0.0, w), tuple(cov))


def imu(t, rpy=(0.0, 0.0, 0.0), gyro=(0.0, 0.0, 0.0), ovar=1e-4, gvar=1e-6):
    return ImuSample("imu", t, rot.from_rpy(*rpy), (ovar, 0, 0, 0, ovar, 0, 0, 0, ovar), gyro,
                     (gvar, 0, 0, 0, gvar, 0, 0, 0, gvar))


def plans_made(monkeypatch) -> list[int]:
    """The sample counts of every ``FusionCore.snapshot_plan`` made in this process from here on (``monkeypatch``:
    the test's fixture, which restores the method after it): how many plans a replay or tune made."""
    from fusiond.core.fusion import FusionCore

    made: list[int] = []
    plan_of = FusionCore.snapshot_plan

    def counted(core, samples):
        made.append(len(samples))
        return plan_of(core, samples)

    monkeypatch.setattr(FusionCore, "snapshot_plan", counted)
    return made
