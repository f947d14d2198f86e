"""An IMU configured to give its orientation whose messages never let one be fused.

``orientation = "roll_pitch"`` (or absolute, relative) fuses the message's orientation where its covariance says
it is measured: covariance[0] = -1 is "no orientation" (sensor_msgs/Imu), and an angle whose stated sigma is beyond
``orientation_max_sigma`` (1e6 on the diagonal, a driver's "unknown") is "not measured" (core/sensors/imu). A
driver stating every sample so makes the key say one thing and the filter do another, with nothing in the
summary but an orientation channel that never appears: roll and pitch then come from the accelerometer (or
nothing), and the yaw that ``yaw_across_gaps`` would carry across a logging gap is not read. On the F1/10 with
its IMU covariances at 1e6 the heading error doubled (13.97 -> 27.95 deg) against the same orientation stated.
"""

from __future__ import annotations

from ...core.sensors.registry import kind_of
from ..check import BaseCheck
from ..evidence import Evidence
from ..lost import none_fused
from ..verdict import Verdict, sensor_key

__all__ = ["OrientationUnfused"]


class OrientationUnfused(BaseCheck):
    """An IMU whose orientation the config asks for and none of whose samples gave one."""

    name = "orientation_unfused"

    def run(self, ev: Evidence) -> list[Verdict]:
        out = []
        for sc in ev.config.sensors:
            if not (kind_of(sc).inertial and sc.fuses_orientation) or sc.orientation_noise is not None:
                continue  # not asked for, or stated by the config (a driver's covariance then does not matter)
            received = (ev.stats or {}).get(sc.name, {}).get("received", 0)
            ch = ev.channels.get((sc.name, "orientation"))
            # none applied: the input verdict's; two_d_mode holds roll and pitch whatever the messages state
            if (received == 0 or none_fused(ev.stats, sc.name) or ev.config.filter.two_d_mode
                    or (ch is not None and ch.n > 0)):
                continue
            tilt = ("roll and pitch come from its accelerometer's gravity instead (tilt_from_gravity)"
                    if sc.tilt_from_gravity else "nothing gives roll and pitch")
            out.append(Verdict(sc.name, "orientation", "warn",
                               f"orientation = \"{sc.orientation}\", but none of its {received} samples' orientation "
                               "was fused: they state it as absent (covariance[0] = -1) or not measured (a sigma "
                               f"beyond orientation_max_sigma, {sc.orientation_max_sigma:g} rad: a driver's 1e6 for "
                               f"\"unknown\"). So {tilt}, and no yaw of it is carried across logging gaps. If the "
                               "driver does measure the orientation, state its noise",
                               sensor_key(sc.name, "orientation_noise"),
                               evidence={"samples": float(received)}))
        return out
