"""What the doctor and the tuner ask a sensor's kind: answered by the kind's own package, so that no
module outside core/sensors/ reads a kind's config strings or tests its config class."""

from __future__ import annotations

import pytest

from fusiond.config import ImuSensor


@pytest.mark.parametrize("orientation, fused, yaw, absolute, relative, tilt_only, rows", [
    ("absolute", True, True, True, False, False, (0, 1, 2)),
    ("relative", True, True, False, True, False, (0, 1, 2)),
    ("roll_pitch", True, False, False, False, True, (0, 1)),
    ("off", False, False, False, False, False, ()),
])
def test_the_imu_table_names_what_its_orientation_mode_fuses(orientation, fused, yaw, absolute, relative, tilt_only,
                                                             rows):
    imu = ImuSensor(name="imu", key="imu", orientation=orientation)
    assert (imu.fuses_orientation, imu.fuses_yaw, imu.absolute_yaw, imu.relative_yaw, imu.roll_pitch_only,
            imu.orientation_rows) == (fused, yaw, absolute, relative, tilt_only, rows)
    # roll and pitch come from the IMU in every mode while gravity gives them; "off" without it gives none
    assert imu.tilt_from_imu
    assert ImuSensor(name="imu", key="imu", orientation=orientation, tilt_from_gravity=False).tilt_from_imu == fused
