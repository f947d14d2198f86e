"""The IMU's own axes and base_link's: where a noise stated per IMU axis lands.

``orientation_noise`` (like the message's covariance) is stated in the IMU's axes; the filter fuses
base_link roll, pitch (and yaw). Through the mount R (IMU -> base, ``extrinsic_rpy``) a diagonal
IMU-frame variance C gives base component k the variance sum_j R_kj^2 C_j. An IMU axis is *seen* by
a set of base rows when more than half of its variance lands on them: those are the axes a fit of
the fused rows can inform, and the ones the doctor's figure and tune's value both name, so that the
two speak of the same numbers (an IMU rolled by 90 degrees fuses base pitch from its own yaw axis).
"""

from __future__ import annotations

from ....estimator import rotation as rot

SEEN = 0.5  # an IMU axis is seen by base rows onto which more than this share of its variance lands


def weights(extrinsic_rpy: tuple[float, float, float]) -> list[list[float]]:
    """W[k][j] = R_kj^2: the share of IMU axis j's variance landing on base component k."""
    R = rot.matrix(rot.from_rpy(*extrinsic_rpy))
    return [[float(R[k, j]) ** 2 for j in range(3)] for k in range(3)]


def seen_axes(extrinsic_rpy: tuple[float, float, float], base_rows: tuple[int, ...]) -> tuple[int, ...]:
    """The IMU axes (0 x/roll, 1 y/pitch, 2 z/yaw) whose variance lands mostly on ``base_rows``."""
    W = weights(extrinsic_rpy)
    return tuple(j for j in range(3) if sum(W[k][j] for k in base_rows) > SEEN)


__all__ = ["SEEN", "seen_axes", "weights"]
