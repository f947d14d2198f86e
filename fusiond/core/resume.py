"""What a restarted filter needs to go on where it stopped, and whose it is.

A daemon that restarts (an update, a crash, a watchdog) would otherwise begin again at the
origin with every learnt quantity at its prior: gyro bias, wheel and gyro scales, the yaw
offset of a magnetometer, the GPS datum and heading. ``ResumeState`` is the filter's state
at one stamp, reduced to what defines it: the nominal state and its full covariance (every
block, so biases keep their correlations), the world frame (defined, heading known, the
ENU datum) and each sensor's observed period. What re-forms in the first seconds is left
out on purpose, as ``FusionCore.set_pose`` leaves it: held inputs (the robot is taken to be
at rest until the next odometry), the late-data history, a relative IMU's yaw offset and a
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

__all__ = ["RESUME_VERSION", "ResumeState", "state_fingerprint"]

RESUME_VERSION = 1  # bumped when the fields or their meaning change: an older state is then refused


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
