"""What each kind of sensor sample does to the filter state: one module per kind.

Each ``apply_*`` takes the core (layout, masks, config), the state to change, the
sensor index, the converted input and its stamp, and returns the diagnostics
records of the updates it made (when ``emit``). Adding a sensor kind is a new
module here plus its policy in ``core/sensors.py``; the core's time handling
does not change.
"""

from .gps import apply_gps
from .imu import apply_imu
from .odom import apply_odom
from .pose import accumulate_motion, apply_pose

__all__ = ["apply_gps", "apply_imu", "apply_odom", "apply_pose", "accumulate_motion"]
