"""The doctor's word on the F1/10 recording's 26.4 s logging gap at 116 s (``doctor/checks/gap_heading.py``), with the
IMU's roll/pitch fused and its yaw not: the gap comes before the first standstill (146 s), so the gyro's bias is not
learned yet and the filter's heading drifts with it. With yaw_across_gaps (the default) the core turns the heading by
the IMU's change less the share of its drift it can tell from the heading's own (core/sensors/imu/gap_turn.py), and
the doctor, measuring the drift over the whole run against the gyro as it reads at rest, finds that turn within
its tolerance: nothing named. Off, the doctor names the missed turn and the key. Skipped without the recording."""

from __future__ import annotations

from fusiond.config import loads
from fusiond.doctor.checks.gap_heading import GAP_TURN_RAD
from fusiond.replay.run import replay

from tests.support.recordings import DATA, needs

F110 = DATA / "f110_ds2"

pytestmark = needs("f110_ds2", "the F1/10 recording")

CONFIG = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
twist_frame = "body"

[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
orientation = "roll_pitch"
angular_velocity = true
"""


def test_the_gap_turn_agrees_with_the_doctor_and_without_it_the_doctor_names_the_key():
    result = replay([F110], loads(CONFIG), progress=False)
    imu = next(m for m in result.core.models if hasattr(m, "gap_turns"))
    assert imu.gap_turns == 2  # the 26.4 s gap and the 1.1 s one
    assert not [v for v in result.verdicts() if v.channel == "heading_across_gaps"], result.verdicts()
    off = replay([F110], loads(CONFIG + "yaw_across_gaps = false\n"), progress=False)
    v = next(v for v in off.verdicts() if v.sensor == "imu" and v.channel == "heading_across_gaps")
    assert abs(v.evidence["largest_missed_turn_rad"]) > GAP_TURN_RAD and v.suggestion == "yaw_across_gaps = true", v
    assert abs(v.evidence["estimate_turn_rad"]) < GAP_TURN_RAD, v.evidence  # held: the old heading
