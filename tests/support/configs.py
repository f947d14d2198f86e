"""The config most fusion tests start from: one odometry ("wheel", key "odom") and one IMU
("imu", key "imu", gyro fused), plus optional GPS and pose sensors and extra lines per table."""

from __future__ import annotations

from fusiond.config import Config, loads


def robot_config(gps: str | None = None, pose: str | None = None, odom: str = "", imu: str = "",
                 filt: str = "", orientation: str = "roll_pitch", gyro: bool = True, imu_key: str = "imu") -> Config:
    """``gps``/``pose``: None for no such sensor, else the extra lines of its table; ``gyro``: whether
    the IMU's angular velocity is fused."""
    return loads(robot_config_text(gps, pose, odom, imu, filt, orientation, gyro, imu_key))


def robot_config_text(gps: str | None = None, pose: str | None = None, odom: str = "", imu: str = "",
                      filt: str = "", orientation: str = "roll_pitch", gyro: bool = True, imu_key: str = "imu") -> str:
    """The TOML of ``robot_config`` (for a test that needs the config as a file)."""
    text = f"""
[filter]
{filt}
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
{odom}
[[sensors]]
name = "imu"
kind = "imu"
key = "{imu_key}"
orientation = "{orientation}"
angular_velocity = {"true" if gyro else "false"}
{imu}
"""
    if gps is not None:
        text += f'[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "gps"\n{gps}\n'
    if pose is not None:
        text += f'[[sensors]]\nname = "pose"\nkind = "pose"\nkey = "pose"\n{pose}\n'
    return text


def loopback_daemon_config(output: str = "", imu: str = "", extra: str = "") -> Config:
    """The in-process daemon tests' config: outputs on "t/..." keys (plus the ``output`` lines), odometry
    on t/odom and an IMU on t/imu (plus the ``imu`` lines), then ``extra`` tables (another sensor)."""
    return loads(f"""
[output]
pose_key = "t/pose"
odometry_key = "t/odometry"
diagnostics_key = "t/diagnostics"
health_key = "t/health"
{output}
[[sensors]]
name = "wheel"
kind = "odom"
key = "t/odom"
[[sensors]]
name = "imu"
kind = "imu"
key = "t/imu"
{imu}
{extra}""")


def sensor_tables(imu: str = "", imu_key: str = "imu", gps: str | None = None, gps_key: str = "gps") -> str:
    """Just the ``[[sensors]]`` tables of the usual robot, for a test that writes the other tables itself:
    odometry "wheel" on key "odom", an IMU "imu" on ``imu_key`` (plus the ``imu`` lines) and, when ``gps``
    is not None, a GPS "gps" on ``gps_key`` (plus the ``gps`` lines)."""
    text = f'[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n' \
           f'[[sensors]]\nname = "imu"\nkind = "imu"\nkey = "{imu_key}"\n{imu}\n'
    if gps is not None:
        text += f'[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "{gps_key}"\n{gps}\n'
    return text
