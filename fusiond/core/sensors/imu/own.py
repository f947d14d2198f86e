"""The IMU's slice of the filter state (``FilterState.own[index]``): what it remembers between messages.

Immutable, so that history snapshots share it; a model replaces it with ``msgspec.structs.replace``.
"""

from __future__ import annotations

import msgspec

from .gyro_bias import BiasLearning


class ImuOwn(msgspec.Struct, frozen=True, gc=False):
    """The IMU's slice of the filter state (immutable: history snapshots share it)."""

    yaw_offset: float | None = None  # relative orientation: the yaw read at the first message minus the filter's
    yaw_residual: float | None = None  # absolute yaw: reading - heading - offset after the previous sample ...
    yaw_stamp: float | None = None  # ... and its stamp (the yaw-jump gate)
    adaptive: tuple[float, float, int] = (1.0, 0.0, 0)  # R scale of the orientation, window NIS/dof sum, count
    bias: BiasLearning = BiasLearning()  # the standstill windows of the gyro-bias learning
    gravity: tuple | None = None  # (start stamp, samples, sums of x, y, z) of the specific force being averaged
    orientation_credit: tuple[float, float] | None = None  # (credit, stamp): ``orientation_rate_hz``'s bucket
    # yaw_across_gaps: (stamp, the IMU's yaw, the filter's yaw, the fused orientations' period, the heading's
    # variance, standing still: odometry zero and gyro quiet, the state's wheel_turn)
    # at the last fused orientation, and whether the IMU's yaw has ever moved; its drift (``_learn_drift``)
    yaw_mark: tuple[float, float, float, float, float, bool, float] | None = None
    yaw_live: bool = False
    yaw_drift: tuple[float, float, float, int, float, float, int] | None = None
    wheel_yaw: tuple[float, float, float, float, float] | None = None  # ``_learn_wheel_yaw``'s sums


__all__ = ["ImuOwn"]
