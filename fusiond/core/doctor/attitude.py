"""IMU attitude: orientation noise in the frame its key applies in, and the mounting (lean).

``orientation_noise`` is stated in the IMU's own axes (the policy rotates it into
base_link with ``extrinsic_rpy``), while the innovations are base-frame roll,
pitch, yaw. For a diagonal IMU-frame noise C, base component k has variance
sum_j R_kj^2 C_j (R: IMU -> base); the doctor solves that for the IMU-axis sigmas
it can see, so a noise measured on base pitch of an IMU rolled by 90 degrees is
reported where it belongs: on the IMU's yaw.

A steady lean of the estimate on level ground is a mounting rotation missing from
``extrinsic_rpy``; the verdict prints the full mount (both tilt axes, composed
with the configured one) as a ready-to-paste value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...config import ImuSensor
from ...estimator import rotation as rot
from .nis import ChannelStats
from .verdict import Verdict, sensor_key

LEAN_RAD = 0.03  # a mean lean of ~1.7 degrees that barely varies
AXES = ("roll", "pitch", "yaw")


@dataclass
class TiltStats:
    """Estimated roll/pitch over the run: a steady lean on level ground is a mounting error."""

    n: int = 0
    sums: list[float] = field(default_factory=lambda: [0.0, 0.0])
    squares: list[float] = field(default_factory=lambda: [0.0, 0.0])

    def add(self, roll: float, pitch: float) -> None:
        self.n += 1
        for i, a in enumerate((roll, pitch)):
            self.sums[i] += a
            self.squares[i] += a * a


def imu_axis_sigmas(ch: ChannelStats, imu: ImuSensor) -> tuple[list[float], list[str]]:
    """Measured innovation sigmas in the IMU's axes (where orientation_noise applies), and for each
    IMU axis the base component it mostly lands on. Axes the channel cannot see keep the configured
    value (or NaN)."""
    R = rot.matrix(rot.from_rpy(*imu.extrinsic_rpy))  # IMU -> base
    rows = [AXES.index(c) for c in ch.components]
    M = ch.second_moment()
    W = np.array([[R[k, j] ** 2 for j in range(3)] for k in rows])
    var_base = np.array([M[i][i] for i in range(len(rows))])
    seen = [j for j in range(3) if W[:, j].sum() > 0.5]
    configured = list(imu.orientation_noise) if imu.orientation_noise is not None else [math.nan] * 3
    out = list(configured)
    if seen:
        fixed = [j for j in range(3) if j not in seen]
        rhs = var_base - sum((W[:, j] * (configured[j] ** 2 if math.isfinite(configured[j]) else 0.0)
                              for j in fixed), np.zeros(len(rows)))
        sol, *_ = np.linalg.lstsq(W[:, seen], rhs, rcond=None)
        for j, v in zip(seen, sol):
            out[j] = math.sqrt(max(float(v), imu.orientation_min_sigma ** 2))
    lands = [AXES[int(np.argmax(np.abs(R[:, j])))] for j in range(3)]
    return out, lands


def noise_suggestion(ch: ChannelStats, imu: ImuSensor) -> tuple[str, str]:
    """('orientation_noise = [...]', a note on the frame) in the IMU's axes."""
    sig, lands = imu_axis_sigmas(ch, imu)
    filled = [s if math.isfinite(s) else 1.0 for s in sig]
    note = "in the IMU's own axes (the key applies before extrinsic_rpy)"
    moved = [f"IMU {AXES[j]} lands on base {lands[j]}" for j in range(3) if lands[j] != AXES[j]]
    if moved:
        note += ": " + ", ".join(moved)
    return "orientation_noise = [" + ", ".join(f"{v:.4f}" for v in filled) + "]", note


def lean_verdict(tilt: TiltStats, imu: ImuSensor | None, min_updates: int = 50) -> Verdict | None:
    if tilt.n < min_updates or imu is None:
        return None
    means, stds = [], []
    for k in range(2):
        m = tilt.sums[k] / tilt.n
        means.append(m)
        stds.append(math.sqrt(max(tilt.squares[k] / tilt.n - m * m, 0.0)))
    leaning = [k for k in range(2) if abs(means[k]) > LEAN_RAD and stds[k] < 0.5 * abs(means[k])]
    if not leaning:
        return None
    # estimated base = q_imu * q_cfg^-1 = yaw * q_true * q_cfg^-1; level ground: q_true = tilt * q_cfg
    q_true = rot.mul(rot.from_rpy(means[0], means[1], 0.0), rot.from_rpy(*imu.extrinsic_rpy))
    rpy = rot.to_rpy(q_true)
    what = " and ".join(f"{('roll', 'pitch')[k]} {means[k]:+.3f} rad (std {stds[k]:.3f})" for k in leaning)
    return Verdict(imu.name, "attitude", "warn",
                   f"the robot leans by {what} on average: on level ground that is an IMU mounting rotation "
                   "missing from, or wrong in, extrinsic_rpy (the body-frame twist then climbs or sinks). The full "
                   "mount, both tilt axes composed with the configured one, is below",
                   sensor_key(imu.name, "extrinsic_rpy"),
                   "extrinsic_rpy = [" + ", ".join(f"{v:.4f}" for v in rpy) + "]",
                   {"lean_roll_rad": means[0], "lean_pitch_rad": means[1]})
