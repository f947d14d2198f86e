"""Held-back fixes (or poses): how well a config predicts the absolute positions it was not given.

The likelihood judges a noise by how well the filter predicts its own innovations. That can
reward the wrong thing: a GPS whose error is coloured (multipath, a receiver's slow wander) has
innovations that a too-small white noise "explains" better, while the positions get worse; on a
held-out skid-steer, a fit on the likelihood alone took `position_noise` from the stated 0.8 m to
0.04 m, after which the gate rejected 263 fixes and the altitude ran to -21 m. What a user cares
about is where the robot is. So a change of noise is also judged where the truth is known best:
every HOLD_EVERY-th fix of the absolute sensor (a GPS, or an absolute pose: motion capture, a
ceiling camera) is held back from the replay, and the filter's position at its stamp (interpolated
between the published poses around it, the antenna's or marker's lever arm applied) is compared
with it, horizontally and vertically apart (a consumer receiver's altitude is a different sensor
from its horizontal position). The filter has not seen that fix;
it has seen the ones around it, which is how it runs.

An axis whose GPS error is slow against the recording (a Gauss-Markov time constant the recording
spans fewer than SPAN_TAUS of, the kind's ``slow_errors``) is not scored: the held fixes share that error
with their fused neighbours, so a config that follows the receiver's wander predicts them better while
it moves away from the truth. On the highway car's 60 s (altitude tau 300 s), a tighter horizontal noise
put z 0.66 m RMS from the held fixes' altitude (1.30 m as configured) and 0.71 m from the reference's
(0.45 m as configured).

The score is the RMS of those errors. It carries the held fixes' own noise, the same for every
config compared, so a difference between two configs is the filter's; but that noise makes the RMS
itself uncertain, so "worse" is a paired test over the same fixes: the mean of the per-fix
differences of squared error beyond WORSE_Z of its standard error (one-sided 5 %: two equally
good configs are called different one time in twenty, and then the change is refused, never made),
and by more than RELEVANT of the error: a consistent change of a millimetre is real and no worse for
anyone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..estimator.backend import Backend
from ..config import Config
from ..core.fusion import FusionCore
from ..core.layout import absolute_sensor, fuses_height
from ..core.sensors.registry import kind_of
from ..estimator import rotation as rot

HOLD_EVERY = 5  # every 5th fix held back: a fifth of the fixes scored, four fifths still fused
MAX_GAP_S = 0.5  # a held fix is scored only between published poses at most this far from its stamp
MIN_FIXES = 10  # fewer held fixes than this score nothing (an RMS of a handful says little)
NO_FIX = -1  # NavSatStatus.STATUS_NO_FIX
WORSE_Z = 1.645  # one-sided 5 % normal quantile of the paired comparison (module doc)
RELEVANT = 0.01  # a change of the RMS error smaller than 1 % of it is no change


@dataclass(frozen=True)
class Prediction:
    """The RMS error of the filter's position at the held-back fixes (m), horizontal and vertical
    (None: not scored, e.g. no altitude fused), and how many fixes were scored."""

    horizontal: float | None
    vertical: float | None
    fixes: int
    squared: dict[int, tuple[float, float]] | None = None  # held fix index -> (horizontal, vertical) error^2

    def worse_than(self, other: "Prediction") -> bool:
        """Is this prediction worse than ``other`` on either axis both scored, by the paired test over the
        fixes both scored (module doc)?"""
        if not self.squared or not other.squared:
            return False
        common = [k for k in self.squared if k in other.squared]
        if len(common) < MIN_FIXES:
            return False
        axes = [i for i, (mine, theirs) in enumerate(((self.horizontal, other.horizontal), (self.vertical, other.vertical)))
                if mine is not None and theirs is not None]
        for axis in axes:
            mine = np.array([self.squared[k][axis] for k in common])
            theirs = np.array([other.squared[k][axis] for k in common])
            d = mine - theirs
            se = float(d.std(ddof=1)) / math.sqrt(d.size)
            if d.mean() > WORSE_Z * se and mine.mean() > (1.0 + RELEVANT) ** 2 * theirs.mean():
                return True
        return False

    def describe(self) -> str:
        parts = []
        if self.horizontal is not None:
            parts.append(f"horizontal {self.horizontal:.3f} m")
        if self.vertical is not None:
            parts.append(f"vertical {self.vertical:.3f} m")
        return ", ".join(parts) or "not scored"


def gps_sensor(cfg: Config):
    """The GPS that defines the world frame (an absolute sensor whose kind is geodetic), or None (a pose
    sensor's or no absolute sensor)."""
    s = world_sensor(cfg)
    return s if s is not None and kind_of(s).geodetic else None


def world_sensor(cfg: Config):
    """The absolute sensor whose positions the held-back check scores: the first that defines the world
    frame (a GPS, or a pose that is not differential), or None."""
    for s in cfg.sensors:
        if absolute_sensor(s):
            return s
    return None


def split(samples: Sequence[object], cfg: Config, every: int = HOLD_EVERY) -> tuple[list, list]:
    """(the samples with every ``every``-th fix or pose of the world's absolute sensor held back, those). GPS
    messages without a fix (status -1) are counted neither way: they are not positions."""
    world = world_sensor(cfg)
    if world is None:
        return list(samples), []
    sample_type = kind_of(world).sample_type
    kept: list = []
    held: list = []
    n = 0
    for s in samples:
        if type(s) is sample_type and s.sensor == world.name and getattr(s, "status", 0) != NO_FIX:
            n += 1
            if n % every == 0:
                held.append(s)
                continue
        kept.append(s)
    return kept, held


def predict(cfg: Config, kept: Sequence[object], held: Sequence[object], backend: Backend | None = None) -> Prediction:
    """Replay ``kept`` through a fresh core (``backend``: the estimator's, ``FusionCore``) and score its position
    at the ``held`` fixes or poses (module doc)."""
    world = world_sensor(cfg)
    if world is None or len(held) < MIN_FIXES:
        return Prediction(None, None, 0)
    geodetic = kind_of(world).geodetic
    core = FusionCore(cfg, backend)
    ingest = core.ingest
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    for s in kept:
        step = ingest(s)
        if step.publish and core.initialised:
            t, pose = core.pose()
            if stamps and t <= stamps[-1]:
                if t < stamps[-1]:  # the clock went back (a reset): the track before it is another run
                    stamps.clear()
                    poses.clear()
                else:
                    poses[-1] = pose.copy()
                    continue
            stamps.append(t)
            poses.append(pose.copy())
    frame = core.state.enu if core.state is not None else None
    if (geodetic and frame is None) or len(stamps) < 2:
        return Prediction(None, None, 0)
    t = np.asarray(stamps)
    p = np.asarray(poses)
    lever = np.asarray(world.extrinsic_xyz, dtype=float)
    antenna = p[:, :3] if not lever.any() else p[:, :3] + np.array([rot.matrix(q) @ lever for q in p[:, 3:7]])
    dh, dv = [], []
    squared: dict[int, tuple[float, float]] = {}
    for index, fix in enumerate(held):
        k = int(np.searchsorted(t, fix.stamp))
        if k == 0 or k >= t.size or fix.stamp - t[k - 1] > MAX_GAP_S or t[k] - fix.stamp > MAX_GAP_S:
            continue
        w = (fix.stamp - t[k - 1]) / (t[k] - t[k - 1])
        at = (1.0 - w) * antenna[k - 1] + w * antenna[k]
        e, n, u = frame.enu(fix.latitude, fix.longitude, fix.altitude) if geodetic else fix.position
        dh.append((at[0] - e) ** 2 + (at[1] - n) ** 2)
        dv.append((at[2] - u) ** 2)
        squared[index] = (dh[-1], dv[-1])
    if len(dh) < MIN_FIXES:
        return Prediction(None, None, len(dh))
    slow = kind_of(world).slow_errors(world, held[-1].stamp - held[0].stamp)
    horizontal = None if "horizontal" in slow else math.sqrt(sum(dh) / len(dh))
    vertical = None if "vertical" in slow or not fuses_height(cfg, world) else math.sqrt(sum(dv) / len(dv))
    return Prediction(horizontal, vertical, len(dh), squared)


__all__ = ["HOLD_EVERY", "Prediction", "RELEVANT", "WORSE_Z", "gps_sensor", "predict", "split", "world_sensor"]
