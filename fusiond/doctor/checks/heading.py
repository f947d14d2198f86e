"""Heading cross-check: the IMU's absolute yaw against the gyro, the wheels and the GPS track.

A magnetometer yaw carries a constant offset (declination, mounting) and a slow
disturbance near motors and steel. Neither shows in the IMU's own NIS when the
filter follows the IMU; both show against other sources:

* against the integrated gyro, over windows of a minute: a gyro bias is a linear
  drift and a gyro scale error is proportional to the turn, so after fitting
  ``a + b t + c gyro_heading`` what is left is the IMU yaw wandering (the wheels,
  fitted the same way, say whether the gyro itself is the odd one out);
* against the GPS track direction (chords of the fixes while moving): the mean is
  the IMU's yaw offset, the rest its wander (beyond the track's own noise).
"""

from __future__ import annotations

import math

import numpy as np

from ...config import Config, ImuSensor
from ...core.layout import absolute_sensor
from ...core.sensors.registry import kind_of
from ...core.sensors.gps import HEADING_READY_SIGMA
from ..check import BaseCheck, found
from ..evidence import Evidence
from ..heading import WANDER_RAD, detrended_rms, gps_sigma, imu_vs_gyro, imu_yaw_drift, timed, vs_gyro, wrap
from ..series import Series
from ..verdict import Verdict, sensor_key

__all__ = ["Heading", "heading_check", "TRACK_OFFSET_RAD"]

TRACK_OFFSET_RAD = 0.05  # a mean IMU-vs-track offset this large is worth a yaw_offset
# ... unless the filter estimates it: an offset within this many of its prior's sigmas (yaw_offset_sigma) is one
# a Gaussian prior takes up (3: 99.7 % of the offsets the prior states)
OFFSET_PRIOR_SIGMAS = 3.0
DRIFT_RAD_S = 0.002  # the IMU yaw's own drift (against the gyro, its bias at rest removed) that is no heading:


def _offset_line(imu: ImuSensor, offset: float) -> str:
    """The line that states an absolute yaw's offset from the GPS track (corrected = raw + yaw_offset)."""
    return f"yaw_offset = {imu.yaw_offset - offset:.4f}"


def estimate_vs_gyro(series: Series) -> float:
    """How far the filter's own heading wanders against the integrated raw gyro (as ``imu_vs_gyro``: a bias
    and a scale removed per window): what of a disturbed IMU yaw reached the estimate, once its heading is
    known (attitude variance within HEADING_READY_SIGMA^2: a magnetometer disturbed at start-up is
    followed while nothing else gives the heading, and only then). NaN when they overlap in fewer than 10
    bins, or the heading never became known."""
    ye = np.unwrap(np.asarray(series.est_yaw)) if series.est_yaw else np.empty(0)
    te = np.asarray(series.est_t)
    known = np.asarray(series.est_att_var) <= HEADING_READY_SIGMA**2
    if len(known) != len(te) or not known.any():
        return math.nan
    first = int(np.argmax(known))
    compared = vs_gyro(series, te[first:], ye[first:], series.odom_breaks)
    return compared[0] if compared is not None else math.nan


def track_segments(series: Series, min_length: float, max_s: float = 30.0) -> list[tuple[float, float, float, float]]:
    """(t0, t1, track direction rad, chord length m) between fixes at least min_length apart."""
    t, e, n = np.array(series.gps_t), np.array(series.gps_e), np.array(series.gps_n)
    order = np.argsort(t)
    t, e, n = t[order], e[order], n[order]
    out = []
    i = 0
    while i < len(t) - 1:
        end = int(np.searchsorted(t, t[i] + max_s, side="right"))  # only fixes within max_s: O(n) overall
        d = np.hypot(e[i + 1:end] - e[i], n[i + 1:end] - n[i])
        far = np.nonzero(d >= min_length)[0]
        if not len(far):
            i += 1  # standing, or too slow from here: try the next fix
            continue
        j = i + 1 + int(far[0])
        out.append((float(t[i]), float(t[j]), math.atan2(n[j] - n[i], e[j] - e[i]), float(d[far[0]])))
        i = j
    return out


def yaw_along(series: Series, ti: np.ndarray, yi: np.ndarray, t0: float, t1: float) -> float:
    """The direction the IMU's yaw says the vehicle moved in from t0 to t1: that of the sum of the
    odometry's speed along the yaw, sum v (cos yaw, sin yaw), over the bins between (a GPS chord is
    exactly that displacement, whatever the curvature, and an offset of the yaw turns it by itself).
    The yaw at the chord's middle instant is that direction only on an arc of constant curvature: a
    chord that runs straight, then turns, reads the turn's direction, a bias with the sense of the turns
    (on a skid-steer, a -0.13 rad "offset" of a correct magnetometer). Without two moving bins inside,
    the middle instant's yaw."""
    to, vo = np.asarray(series.odom_t), np.asarray(series.odom_v)
    lo, hi = np.searchsorted(to, t0, side="left"), np.searchsorted(to, t1, side="right")
    v = vo[lo:hi]
    if hi - lo < 2 or not np.any(v != 0.0):
        return float(np.interp(0.5 * (t0 + t1), ti, yi))
    yaw = np.interp(to[lo:hi], ti, yi)
    return math.atan2(float(np.sum(v * np.sin(yaw))), float(np.sum(v * np.cos(yaw))))


def heading_check(series: Series, cfg: Config) -> Verdict | None:
    """The verdict on an IMU whose absolute yaw is fused, from the other heading sources."""
    imu = next((s for s in cfg.sensors if kind_of(s).inertial and kind_of(s).fuses_yaw(s)),
               None)
    if imu is None or len(series.imu_t) < 10:
        return None
    gps = next((s for s in cfg.sensors if kind_of(s).geodetic), None)
    ti, yi = timed(series.imu_yaw_at, series.imu_yaw)
    if len(ti) < 10:
        return None
    evidence: dict[str, float] = {}
    notes: list[str] = []
    wander = math.nan
    culprit_gyro = False
    compared = imu_vs_gyro(series)
    if compared is not None:
        wander, drift = compared
        evidence["imu_vs_gyro_wander_rad"] = wander
        if math.isfinite(drift):
            evidence["imu_vs_gyro_drift_rad_s"] = drift
        if len(series.odom_t) >= 10 and np.ptp(series.odom_heading) > 0.0:
            tg, hg = timed(series.gyro_heading_at, series.gyro_heading)
            to, ho = timed(series.odom_heading_at, series.odom_heading)
            mo = (to >= tg[0]) & (to <= tg[-1])
            if mo.sum() >= 10:
                g = np.interp(to[mo], tg, hg)
                wheel_vs_gyro, _ = detrended_rms(to[mo], ho[mo] - g, g, [*series.odom_breaks, *series.gyro_breaks])
                wi = np.interp(to[mo], ti, yi)
                wheel_vs_imu, _ = detrended_rms(to[mo], ho[mo] - wi, wi, [*series.odom_breaks, *series.imu_breaks])
                evidence["wheel_vs_gyro_wander_rad"] = wheel_vs_gyro
                if math.isfinite(wheel_vs_gyro) and wheel_vs_gyro < WANDER_RAD:
                    notes.append(f"the wheels agree with the gyro to {wheel_vs_gyro:.3f} rad rms")
                elif math.isfinite(wheel_vs_imu) and wheel_vs_imu < WANDER_RAD <= wander:
                    culprit_gyro = True
    own_drift = _own_drift(series, cfg, imu)
    if math.isfinite(own_drift):
        evidence["imu_yaw_drift_rad_s"] = own_drift
    if abs(own_drift) > DRIFT_RAD_S and not culprit_gyro:
        # checked before the wander: a steady drift is what the detrending takes out
        suggestion = 'orientation = "roll_pitch"' + ("" if imu.angular_velocity else " and angular_velocity = true")
        return Verdict(imu.name, "orientation", "problem",
                       f"the IMU's yaw drifts at {own_drift:+.4f} rad/s ({math.degrees(own_drift) * 60.0:+.1f} deg a "
                       "minute) against the gyro, its bias at rest removed: an AHRS integrating its own gyro (a 6-axis "
                       "IMU), not an absolute heading. Fused, it drags the heading and the gyro bias along. Take "
                       "heading from the gyro and only roll/pitch from the IMU (yaw_across_gaps still carries its "
                       "turns across logging gaps); do not state a smaller orientation_noise",
                       sensor_key(imu.name, "orientation"), suggestion, evidence)
    offset = math.nan
    track_wander = math.nan
    if gps is not None and len(series.gps_t) >= 5:
        sigma = gps_sigma(series, gps)
        length = max(5.0, 10.0 * sigma)
        segs = track_segments(series, length)
        if len(segs) >= 5:
            mids = np.array([(a + b) / 2.0 for a, b, _, _ in segs])
            m = (mids >= ti[0]) & (mids <= ti[-1])
            if m.sum() >= 5:
                tracks = np.array([s[2] for s in segs])[m]
                chords = np.array([s[3] for s in segs])[m]
                d = wrap(np.array([yaw_along(series, ti, yi, a, b) for a, b, _, _ in
                                    (seg for seg, keep in zip(segs, m) if keep)]) - tracks)
                offset = float(math.atan2(np.mean(np.sin(d)), np.mean(np.cos(d))))
                r = wrap(d - offset)
                track_var = np.mean(2.0 * sigma**2 / chords**2)
                n = len(r)
                se = math.sqrt(max(np.mean(r * r), track_var) / n)
                evidence["imu_vs_gps_track_offset_rad"] = offset
                evidence["imu_vs_gps_track_offset_se_rad"] = se
                excess = float(np.mean(r * r) - track_var)
                if excess > 0 and np.mean(r * r) / track_var > 1.0 + 3.0 * math.sqrt(2.0 / n):
                    track_wander = math.sqrt(excess)
                    evidence["imu_vs_gps_track_wander_rad"] = track_wander
                if abs(offset) < max(TRACK_OFFSET_RAD, 3.0 * se) or imu.relative_yaw:
                    offset = math.nan  # not significant (or removed by the relative mode anyway)
    disturbed = (math.isfinite(wander) and wander > WANDER_RAD and not culprit_gyro) or (
        not math.isfinite(wander) and math.isfinite(track_wander) and track_wander > WANDER_RAD)
    key_sensor = imu.name
    # the filter's yaw-offset state, which the IMU kind adds beside the GPS (its prior yaw_offset_sigma)
    offset_estimated = gps is not None and imu.absolute_yaw and imu.yaw_offset_sigma > 0.0
    if culprit_gyro:
        return Verdict(imu.name, "orientation", "warn",
                       f"the integrated gyro wanders against both the IMU yaw and the wheels by {wander:.3f} rad rms "
                       "(beyond a bias or scale): the gyro, not the IMU yaw, is the odd one out",
                       sensor_key(key_sensor, "gyro_noise"), evidence=evidence)
    if disturbed:
        w = wander if math.isfinite(wander) else track_wander
        against = "the integrated gyro" if math.isfinite(wander) else "the GPS track"
        removed = ("once a gyro bias and scale are removed" if math.isfinite(wander)
                   else "beyond the track's own noise")
        msg = (f"the IMU's absolute yaw wanders against {against} by {w:.3f} rad rms {removed}: a "
               "magnetometer-disturbed yaw (motors, steel)")
        if notes:
            msg += "; " + "; ".join(notes)
        held = estimate_vs_gyro(series) if offset_estimated else math.nan
        if math.isfinite(held):
            evidence["estimate_vs_gyro_wander_rad"] = held
        if held <= WANDER_RAD:
            # Beside the GPS the filter estimates the yaw's offset and gates its jumps: its heading did not
            # follow the disturbance, so roll_pitch would only lose the magnetometer's help (a skid-steer's
            # heading rms 0.395 rad with roll_pitch against 0.077 rad absolute: the GPS heading is then found
            # from travel again)
            msg += (f"; the estimate's heading did not follow it ({held:.3f} rad rms against the gyro): the filter's "
                    "yaw-offset state and yaw-jump gate absorb it beside the GPS, keep the yaw absolute")
            if math.isfinite(offset):
                return Verdict(imu.name, "orientation", "warn",
                               msg + f"; it sits {offset:+.3f} rad off the GPS track: correct that (corrected = raw "
                               "+ yaw_offset)", sensor_key(key_sensor, "yaw_offset"),
                               _offset_line(imu, offset), evidence)
            return Verdict(imu.name, "orientation", "warn", msg, evidence=evidence)
        if math.isfinite(offset):
            msg += f"; it also sits {offset:+.3f} rad off the GPS track"
        has_gyro = len(series.gyro_t) >= 10
        suggestion = 'orientation = "roll_pitch"'
        if has_gyro and not imu.angular_velocity:
            suggestion += " and angular_velocity = true"
        msg += (". Take heading from the gyro" if has_gyro else ". Take heading from the other sources") + \
            " and only roll/pitch from the IMU; do not state a smaller orientation_noise while the yaw is disturbed"
        return Verdict(imu.name, "orientation", "problem", msg, sensor_key(key_sensor, "orientation"),
                       suggestion, evidence)
    if math.isfinite(offset):
        said = (f"the IMU's absolute yaw sits {offset:+.3f} rad ({math.degrees(offset):+.1f} deg) off the GPS track "
                f"direction (standard error {evidence['imu_vs_gps_track_offset_se_rad']:.3f} rad): a declination or "
                "mounting offset")
        value = _offset_line(imu, offset)
        if offset_estimated and abs(offset) <= OFFSET_PRIOR_SIGMAS * imu.yaw_offset_sigma:
            # beside the GPS the state's yaw offset, its prior this wide, takes it up from the first fixes: stating
            # it changes the run by the few fixes the estimate needs (the highway car with 0.3 rad added: 1.480 m
            # world stated, 1.481 m estimated)
            return Verdict(imu.name, "orientation", "ok",
                           f"{said}, which the filter estimates beside the GPS (its yaw-offset state, prior "
                           f"yaw_offset_sigma = {imu.yaw_offset_sigma:g} rad; the summary's {imu.name}.yaw_offset). "
                           f"Nothing to change; to state it from the start: {value}", evidence=evidence)
        return Verdict(imu.name, "orientation", "problem",
                       f"{said}. Correct it (corrected = raw + yaw_offset), or use "
                       'orientation = "roll_pitch" with the gyro', sensor_key(key_sensor, "yaw_offset"),
                       value, evidence)
    if evidence:
        said = [text.format(evidence[k]) for k, text in _SAID if k in evidence]
        if imu.absolute_yaw and not any(absolute_sensor(s) for s in cfg.sensors):
            # its wander and drift are measured against the gyro; its constant offset against nothing
            said.append("nothing here gives the heading in the world (no GPS or absolute pose), so its offset "
                        "(yaw_offset, magnetic_declination) cannot be checked: the heading carries whatever it is")
        return Verdict(imu.name, "orientation", "ok", "IMU yaw agrees with the other heading sources: "
                       + "; ".join(said), evidence=evidence)
    return None


# the ok verdict's figures, in words (key, text with the value's place)
_SAID = (
    ("imu_vs_gyro_wander_rad", "it wanders {:.3f} rad rms against the integrated gyro"),
    ("imu_vs_gyro_drift_rad_s", "moves {:+.5f} rad/s against it"),
    ("imu_yaw_drift_rad_s", "its own rate {:+.5f} rad/s (the gyro's bias at rest taken off)"),
    ("imu_vs_gps_track_offset_rad", "it sits {:+.3f} rad off the GPS track"),
    ("imu_vs_gps_track_wander_rad", "wanders {:.3f} rad about it"),
    ("wheel_vs_gyro_wander_rad", "the wheels' heading wanders {:.3f} rad against the gyro"),
    ("estimate_vs_gyro_wander_rad", "the estimate's heading wanders {:.3f} rad against the gyro"),
)


def _own_drift(series: Series, cfg: Config, imu: ImuSensor) -> float:
    """The IMU yaw's own drift rate, rad/s (``imu_yaw_drift``: against the gyro, its bias as it reads at rest).
    The filter's bias estimate will not do: a fused drifting yaw drags it to b - r (the gyro verdict's "moved
    by another source"). NaN without standstills."""
    drift = imu_yaw_drift(series, cfg, imu)
    return drift[1] if drift is not None and drift[2] else math.nan


class Heading(BaseCheck):
    """An IMU's fused yaw against the gyro, the wheels and the GPS track."""

    name = "heading"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(heading_check(ev.series, ev.config))
