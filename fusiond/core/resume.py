"""What a restarted filter needs to go on where it stopped, and whose it is.

A daemon that restarts (an update, a crash, a watchdog) would otherwise begin again at the
origin with every learnt quantity at its prior: gyro bias, wheel and gyro scales, the yaw
offset of a magnetometer, the GPS datum and heading. ``ResumeState`` is the filter's state
at one stamp, reduced to what defines it: the nominal state and its full covariance (every
block, so biases keep their correlations), the world frame (defined, heading known, the
ENU datum) and each sensor's observed period. And the motion inputs held at that stamp
(``HeldMotion``): a daemon restarted while the robot drives resumes across a gap as long as
the restart took, and as across a logging gap the held twist ends where its hold ends and what
the robot may have driven meanwhile at its last speed widens the pose
(``HeldInputs.unheld_motion_var``): a car at 17 m/s restarted 26 s later is ~450 m from the
saved pose, and the first fix must be believed, not gated as an outlier while the published
pose stays 450 m off with a sigma of metres. A state saved without them (an older file) is
taken at rest. What re-forms in the first seconds is left out on purpose, as
``FusionCore.set_pose`` leaves it: the late-data history, a relative IMU's yaw offset and a
differential sensor's previous pose, so neither drags the estimate back.

``fingerprint`` says which configuration a state belongs to: the state layout (block names
and sizes, in order) and the sensor set (name, kind, key), plus the settings that give the
numbers their meaning (two_d_mode, a configured GPS datum). Noise tuning is left out, so a
retuned config still resumes; another robot's file, or one from before a sensor was added,
does not fit and is refused.
"""

from __future__ import annotations

import hashlib

import msgspec

from ..config_tables import Config
from .layout import state_layout
from .sensors.registry import kind_of

__all__ = ["RESUME_VERSION", "HeldMotion", "ResumeState", "state_fingerprint"]

RESUME_VERSION = 1  # bumped when the fields or their meaning change: an older state is then refused


class HeldMotion(msgspec.Struct, frozen=True, kw_only=True):
    """The motion inputs a filter held at its stamp (``FilterState``'s fields of the same names)."""

    last: list[float | None]  # each sensor's newest stamp (None: none yet)
    linear: tuple[float, float, float]
    linear_cov: tuple[float, ...]  # 9
    linear_world: bool
    wheel_angular: tuple[float, float, float]
    wheel_angular_cov: tuple[float, ...]  # 9
    wheel_yaw_measured: bool
    gyro: tuple[float, float, float] | None = None
    gyro_cov: tuple[float, ...] | None = None
    gyro_sensor: int = -1  # the index of the sensor whose rate ``gyro`` is (-1: none held)


class ResumeState(msgspec.Struct, frozen=True, kw_only=True):
    """The filter at ``stamp`` (message time), as ``FusionCore.export_state`` gives it."""

    version: int = RESUME_VERSION
    fingerprint: str  # ``state_fingerprint`` of the config that produced it
    stamp: float  # filter time of the state
    x: list[float]  # nominal state, the layout's order ([x y z qx qy qz qw] first)
    P: list[float]  # error covariance, row-major error_dim x error_dim
    frame_ready: bool  # an absolute sensor has defined the world frame
    heading_ready: bool  # a GPS-referenced heading has been measured
    datum: tuple[float, float, float] | None = None  # the ENU origin (lat deg, lon deg, alt m) a GPS set
    period: list[float] = []  # each sensor's typical message period (s; 0 before it was measured)
    held: HeldMotion | None = None  # the motion inputs held at ``stamp`` (None: taken at rest)


def state_fingerprint(cfg: Config) -> str:
    """A short hash of what makes a saved state fit this config (see the module docstring)."""
    layout = state_layout(cfg)
    datum = next((list(d) for d in (kind_of(s).datum(s) for s in cfg.sensors) if d is not None), None)
    parts = {
        "blocks": [(b.name, b.nominal_size, b.error_size) for b in layout.blocks],
        "sensors": [(s.name, kind_of(s).name, s.key) for s in cfg.sensors],
        "two_d_mode": cfg.filter.two_d_mode,
        "datum": datum,
    }
    return hashlib.sha256(msgspec.json.encode(parts)).hexdigest()[:16]
