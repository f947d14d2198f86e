"""Samples a driver sent for measurements it lost, kept out of the doctor's series.

The brief's "lost measurements reported as perfect": a value of 0 with covariance 0. Two
shapes are unmistakable, and each bends the fits it enters (a 0.2 s bin of 25 m/s wheel
speed with one lost frame reads 10 % slow, a jump of 12 m/s^2 in dv/dt; a lost IMU sample
is 0 g in the mounting fit):

- an IMU sample with no orientation whose rates and specific force are all exactly zero
  (at rest an accelerometer reads gravity);
- one odometry frame of exactly zero twist between two moving ones, the drop to it faster
  than a vehicle can stop (``impossible_stop``, the core's coast test). A zero that lasts
  (a stop, a drive that reads zero while the vehicle coasts on) is kept: the gyro bias
  check reads those.

The odometry case needs the next frame: a zero frame after such a drop waits for it.
"""

from __future__ import annotations

import math

from ..core.sensors import ImuSample, OdomSample
from ..core.inputs import smoothed_period
from ..core.sensors.odom import impossible_stop

__all__ = ["LostSamples", "none_fused"]

_ZERO3 = (0.0, 0.0, 0.0)


class LostSamples:
    """Admits samples in arrival order, holding back at most one zero odometry frame per sensor."""

    def __init__(self) -> None:
        self.imu = 0  # lost IMU samples left out
        self.odom = 0  # lost odometry frames left out
        self._last: dict[str, tuple[float, float]] = {}  # odometry sensor -> (stamp, speed) of its newest frame
        self._period: dict[str, float] = {}  # odometry sensor -> typical interval between its moving frames
        self._waiting: dict[str, OdomSample] = {}  # a zero frame after an impossible drop, until the next one

    def admit(self, sample) -> list:
        """The samples to pass on now (none, this one, or a held zero frame and this one)."""
        kind = type(sample)
        if kind is ImuSample:
            if (sample.angular_velocity == _ZERO3 and sample.linear_acceleration == _ZERO3
                    and (not any(sample.orientation) or sample.orientation_covariance[0] == -1.0)):
                self.imu += 1
                return []
            return [sample]
        if kind is not OdomSample:
            return [sample]
        name = sample.sensor
        zero = sample.linear == _ZERO3 and sample.angular == _ZERO3
        out = []
        held = self._waiting.pop(name, None)
        if held is not None:
            if zero:
                out.append(held)  # the zero lasts: a stop or a coast, not a lost frame
            else:
                self.odom += 1
        last = self._last.get(name)
        speed = math.hypot(*sample.linear)
        if last is not None and not zero and sample.stamp > last[0] and last[1] > 0.0:
            self._period[name] = smoothed_period(self._period.get(name, 0.0), sample.stamp - last[0])
        if zero and held is None and last is not None and sample.stamp > last[0]:
            if impossible_stop(last[1], sample.stamp - last[0], self._period.get(name, 0.0)):
                self._waiting[name] = sample
                self._last[name] = (sample.stamp, 0.0)
                return out
        self._last[name] = (sample.stamp, speed)
        out.append(sample)
        return out

    def flush(self) -> None:
        """The end of the stream: a zero frame still waiting is the last one, after a drop no vehicle
        makes and with nothing after it to make it a coast: lost."""
        self.odom += len(self._waiting)
        self._waiting.clear()


def none_fused(stats: dict[str, dict] | None, name: str) -> bool:
    """Did sensor ``name`` send samples of which the filter applied none (stamps of 0, another clock)? Then the
    input verdict (its drops by reason) says why, and a check of what its samples stated has nothing to judge.
    ``stats``: per sensor {"received", "applied", ...} (None: not known, False)."""
    st = (stats or {}).get(name, {})
    received = st.get("received", 0)
    return received > 0 and st.get("applied", received) == 0
