"""The IMU's tunable keys (``SensorKind.tunables``): its ``gyro_noise`` with the gyro fused, and its
``orientation_noise`` on the IMU axes that land on the base rows its orientation mode fuses (through
``extrinsic_rpy``, ``axes.seen_axes``): the axes the doctor's figure names too."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..tunable import Param, median, own_samples
from .sample import ImuSample
from .table import ImuSensor


def imu_tunables(s: ImuSensor, samples: Sequence[object]) -> list[Param]:
    """``gyro_noise`` (the gyro fused) and ``orientation_noise`` (an orientation fused): from the config,
    else from the messages' median variances, through the floors and "not measured" rules of ``ImuPolicy``."""
    out = []
    mine = own_samples(samples, s.name, ImuSample)
    if s.angular_velocity:
        name = f"{s.name}.gyro_noise"
        if s.gyro_noise is not None:
            out.append(Param(name, s.name, "gyro_noise", None, s.gyro_noise, unit="rad/s",
                             skipped="" if s.gyro_noise > 0.0 else "0 in the config", floor=s.gyro_min_sigma))
        else:
            stated = [m.angular_velocity_covariance for m in mine
                      if len(m.angular_velocity_covariance) == 9 and m.angular_velocity_covariance[0] != -1.0]
            var = median(c[k] for c in stated for k in (0, 4, 8))
            if var is None or not math.isfinite(var) or var < 0.0:
                out.append(Param(name, s.name, "gyro_noise", None, unit="rad/s", skipped=(
                    "no messages" if not mine else "the messages state no gyro covariance (an override would "
                    "start fusing the rates)")))
            else:
                out.append(Param(name, s.name, "gyro_noise", None, max(math.sqrt(var), s.gyro_min_sigma),
                                 "messages (median)", "rad/s", floor=s.gyro_min_sigma))
    if s.fuses_orientation:
        from .axes import seen_axes  # rotation maths (numpy): tune's, not a config load's

        name = f"{s.name}.orientation_noise"
        # the IMU axes (the key's own, before extrinsic_rpy) that land on the base rows the mode fuses
        rows = seen_axes(s.extrinsic_rpy, s.orientation_rows)
        if s.orientation_noise is not None:
            base = tuple(s.orientation_noise)
            out.append(Param(name, s.name, "orientation_noise", rows, base, unit="rad",
                             skipped="" if all(base[i] > 0.0 for i in rows) else "0 in the config",
                             floor=s.orientation_min_sigma))
        else:
            stated = [m.orientation_covariance for m in mine
                      if len(m.orientation_covariance) == 9 and m.orientation_covariance[0] != -1.0]
            medians = [median(c[4 * k] for c in stated) for k in range(3)]
            if not stated:
                out.append(Param(name, s.name, "orientation_noise", rows, unit="rad", skipped=(
                    "no messages" if not mine else "the messages carry no orientation")))
            elif any(v is None or not (0.0 <= v < s.orientation_max_sigma**2) for v in medians):
                out.append(Param(name, s.name, "orientation_noise", rows, unit="rad", skipped=(
                    "the messages state an axis not measured (an override would fuse it)")))
            else:
                base = tuple(max(math.sqrt(v), s.orientation_min_sigma) for v in medians)  # type: ignore[arg-type]
                out.append(Param(name, s.name, "orientation_noise", rows, base, "messages (median)", "rad",
                                 floor=s.orientation_min_sigma))
    return out


__all__ = ["imu_tunables"]
