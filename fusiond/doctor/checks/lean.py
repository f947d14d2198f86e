"""The estimate's lean: against the grade the GPS altitude measures, else its mean over the run.

Without a GPS grade (``lean_verdict``), a steady tilt of the estimate is read as a mounting error,
which holds on level ground only: a car on a highway leans with the road. With a GPS that measures
altitude the road's grade is measured too. The body-frame twist is integrated along the
estimate's pitch theta_est = theta + delta, delta the IMU's pitch in its mount that
``extrinsic_rpy`` does not say; for a vehicle that moves along its x axis (REP-103, pitch
positive nose down)

    dz/dt = -v sin(theta) = -v sin(theta_est - delta) ~ -v sin(theta_est) + delta v cos(theta_est).

Over a chord from fix a to fix b, with Z the climb the estimate implies (the integral of
-v sin theta_est) and D the distance driven along the track (the integral of v cos theta_est),

    r = (u_b - u_a) - (Z_b - Z_a) = delta (D_b - D_a) + (E_b - E_a),

E the fixes' vertical error. The chords are consecutive (``chords.chord_ends``: they start where the
last one ended), so the errors telescope: over a run of chords without a break the sum of r
carries only E at its two ends. Hence delta = sum(r) / sum(d), with, per unbroken run of length
T, Var(E_end - E_start) = 2 sigma_w^2 + 2 sigma_m^2 (1 - exp(-T / tau)): the white noise at the
two ends and the slow wander (the GPS's vertical error state, ``vertical_error_sigma`` /
``vertical_error_tau_s``, else ``error_sigma``'s up / ``error_tau_s``, else the stated sigma as in
``checks/speed.py``). The residuals' Newey-West variance catches errors larger than that model; the verdict
uses the larger.

The fit measures what is left in the estimate: a filter whose pitch already follows the grade
gives delta near 0. A roll in the mount leaves z alone (the vehicle does not move sideways) and is
not seen here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...config import Config, GpsSensor, ImuSensor
from ...core.sensors.registry import kind_of
from ...core.diagnostics import t_quantile
from ...core.layout import fuses_height, state_layout
from ..attitude import TiltStats, full_mount, inverted_lean, lean_of, paste_mount
from ..check import MIN_UPDATES, BaseCheck, found
from ..chords import ASSUMED_TAU_S, CHORD_M, MIN_CHORDS, SCALE_Z_SIGMAS, cumulative, newey_west, wheel_chords
from ..evidence import Evidence
from ..heading import gps_sigma, gps_sigma_up
from ..mounting import MountYaw
from ..nis import ChannelStats
from ..series import Series
from ..verdict import Verdict, sensor_key

__all__ = ["GradeFit", "Lean", "grade_fit", "grade_verdict", "lean_verdict"]

# A pitch error delta sinks or lifts the dead-reckoned z by delta per metre driven: at 0.01 rad, 1 %
# of the distance, twice the 0.5 % below which mounting.py names no yaw error. Smaller: not named.
MOUNT_PITCH_RAD = 0.01
# A Gauss-Markov error state lies within this many of its stationary sigmas but with probability 0.27 %
# (a normal law): a climb over the drive beyond it is no receiver wander, and the vertical error state that
# takes it drags the published height away from the fixes by about that much.
WANDER_SIGMAS = 3.0


@dataclass
class GradeFit:
    """The IMU's mounting pitch error (rad, the sense of a lean: the estimate's pitch minus the body's)."""

    delta: float
    se_model: float
    se_empirical: float
    chords: int
    distance_m: float  # driven over the chords
    runs: int  # unbroken runs of consecutive chords
    state_sigma_m: float = 0.0  # the stationary sigma of the GPS's vertical error state (0: it has none)

    @property
    def se(self) -> float:
        return max(self.se_model, self.se_empirical)

    @property
    def band(self) -> float:
        """Within it the pitch is not named: the tolerance, or SCALE_Z_SIGMAS standard errors of the model (a
        normal quantile), or Student's t of the residuals' (estimated from the chords themselves)."""
        return max(MOUNT_PITCH_RAD, SCALE_Z_SIGMAS * self.se_model, t_quantile(SCALE_Z_SIGMAS, self.chords - 1) * self.se_empirical)

    @property
    def named(self) -> bool:
        return abs(self.delta) > self.band

    @property
    def resolved(self) -> bool:
        """Known well enough to say the mount's pitch agrees with the grade."""
        return self.band <= MOUNT_PITCH_RAD

    def evidence(self) -> dict[str, float]:
        return {"mount_pitch_error_rad": self.delta, "mount_pitch_error_se": self.se,
                "mount_pitch_se_model": self.se_model, "mount_pitch_se_residuals": self.se_empirical,
                "grade_chords": float(self.chords), "grade_distance_m": self.distance_m}


def _vertical_noise(series: Series, gps: GpsSensor) -> tuple[float, float, float, bool]:
    """(sigma_w, sigma_m, tau, state) of the fixes' altitude: white part and slow wander; ``state``: the wander
    is the GPS's own error state, the one its kind puts in the filter (``GpsKind.state_blocks``: the
    three-axis one with ``error_tau_s``, else the vertical one), not the one assumed without such a state."""
    sigma_w = gps_sigma_up(series, gps)
    if gps.error_tau_s > 0.0 and gps.error_sigma is not None:
        return sigma_w, float(gps.error_sigma[2]), float(gps.error_tau_s), True
    if gps.vertical_error_sigma > 0.0:
        return sigma_w, float(gps.vertical_error_sigma), float(gps.vertical_error_tau_s), True
    return sigma_w, sigma_w, ASSUMED_TAU_S, False


def _tilt_from_imu(imu: ImuSensor) -> bool:
    return imu.tilt_from_imu


def grade_fit(series: Series, cfg: Config, altitude: ChannelStats | None = None) -> GradeFit | None:
    """The chord fit of the mounting pitch, or None without a GPS altitude, an IMU tilt or enough chords.
    ``altitude``: the GPS altitude's channel; a fix its gate rejected ends no chord (a receiver's altitude
    that jumps 30 m for a few seconds, which the filter never took, made 30 m chords that widened the fit's
    band past any verdict and left a 37 m height error unnamed)."""
    gps = next((s for s in cfg.sensors if kind_of(s).geodetic), None)
    imu = next((s for s in cfg.sensors if kind_of(s).inertial), None)
    if gps is None or imu is None or not fuses_height(cfg, gps) or not _tilt_from_imu(imu):
        return None
    if len(series.gps_t) < 5 or len(series.odom_t) < 10 or len(series.est_t) < 10:
        return None
    to = np.asarray(series.odom_t)
    v = np.asarray(series.odom_v)
    te = np.asarray(series.est_t)
    pitch = np.interp(to, te, np.asarray(series.est_pitch))
    climb = cumulative(to, -v * np.sin(pitch))
    along = cumulative(to, v * np.cos(pitch))
    sigma_w, sigma_m, tau, state = _vertical_noise(series, gps)
    gt, gu = series.gps_t, series.gps_u
    r, d, ends = [], [], []
    # not across a logging gap or a coast, where the wheels' travel is missing, not the GPS's climb
    usable = None
    if altitude is not None and altitude.keep and any(altitude.rejected_flags):
        gated = {t for t, rejected in zip(altitude.stamps, altitude.rejected_flags) if rejected}
        usable = np.array([t not in gated for t in gt], dtype=bool)  # the same stamps: the filter's clock
    for i, j in wheel_chords(series, cfg, to, cumulative(to, np.abs(v)), max(CHORD_M, 20.0 * gps_sigma(series, gps)),
                             usable):
        t0, t1 = gt[i], gt[j]
        if t0 < te[0] or t1 > te[-1]:
            continue  # before the first estimate (or after the last): no pitch to compare
        dist = float(np.interp(t1, to, along) - np.interp(t0, to, along))
        r.append((gu[j] - gu[i]) - float(np.interp(t1, to, climb) - np.interp(t0, to, climb)))
        d.append(dist)
        ends.append((i, j))
    n = len(r)
    if n < MIN_CHORDS:
        return None
    r_, d_ = np.array(r), np.array(d)
    total = float(d_.sum())
    if abs(total) <= 0.0:
        return None
    delta = float(r_.sum()) / total
    # unbroken runs: a chord that starts on the fix the previous one ended on continues it
    var_n, runs, start = 0.0, 0, None
    for k, (i, j) in enumerate(ends):
        if start is None:
            start = i
        if k + 1 == n or ends[k + 1][0] != j:
            span = abs(gt[j] - gt[start])
            var_n += 2.0 * sigma_w**2 + 2.0 * sigma_m**2 * (1.0 - math.exp(-span / tau))
            runs += 1
            start = None
    se_model = math.sqrt(var_n) / abs(total)
    se_emp = math.sqrt(newey_west((r_ - delta * d_) / total) * n / (n - 1))
    return GradeFit(delta, se_model, se_emp, n, float(np.abs(d_).sum()), runs, sigma_m if state else 0.0)


def _pitch_learned(ev: Evidence) -> bool:
    """Did the filter estimate the twist's pitch? What the run's core says (``Evidence.scales``: not while
    ``pitch_estimation = "auto"`` held it), else what the config asks (a pitch estimated from the start)."""
    if ev.scales is not None:
        return "twist_pitch" in ev.scales
    block = next((b for b in state_layout(ev.config).blocks if b.name == "twist_pitch"), None)
    return block is not None and block.sigma > 0.0


def grade_verdict(fit: GradeFit | None, imu: ImuSensor | None, mount: MountYaw | None,
                  learned: bool = False, altitude: ChannelStats | None = None) -> Verdict | None:
    """The GPS climb's verdict on the IMU's mounting pitch; None when the drive could not tell. ``learned``:
    the filter estimates the twist's pitch (``pitch_estimation``), so the climb itself is already corrected.
    ``altitude``: the GPS altitude's channel, whose verdict the message quotes (the climb can hide in it, or
    push the fixes out of its gate)."""
    if fit is None or imu is None:
        return None
    deg, se_deg = math.degrees(fit.delta), math.degrees(fit.se)
    ev = fit.evidence()
    if fit.named:
        yaw = mount.delta if mount is not None and mount.named else 0.0
        height = abs(fit.delta) * fit.distance_m  # the climb the drive's twist makes that the ground does not
        beyond = not learned and fit.state_sigma_m > 0.0 and height > WANDER_SIGMAS * fit.state_sigma_m
        if learned:
            fate = "which the filter's twist_pitch state learns as the fixes come; stated, it holds from the " \
                   "first metre and in the published attitude too"
        elif beyond:
            ev["unmodelled_climb_m"] = height
            fate = (f"{height:.0f} m over this drive, which the GPS's vertical error state then takes for receiver "
                    f"wander, {height / fit.state_sigma_m:.0f} times the {fit.state_sigma_m:g} m it allows: the "
                    f"published height leaves the fixes by up to about that, {_altitude_reads(altitude)}; "
                    "pitch_estimation = true on the odometry learns it instead")
        else:
            fate = "which the GPS's vertical error state then takes for receiver wander"
        return Verdict(imu.name, "attitude", "problem" if beyond else "warn",
                       f"the GPS altitude climbs against the estimate's pitch by {deg:+.2f} deg (+- {se_deg:.2f}) "
                       f"over {fit.distance_m:.0f} m of driving ({fit.chords} chords): the IMU is pitched by that in "
                       "its mount and extrinsic_rpy does not say so, so the body-frame twist climbs or sinks "
                       f"({abs(fit.delta) * 100:.1f} m of height per 100 m driven, {fate}). The full mount is below",
                       sensor_key(imu.name, "extrinsic_rpy"), paste_mount(full_mount(imu, (0.0, fit.delta), yaw)), ev)
    if fit.resolved:
        return Verdict(imu.name, "attitude", "ok",
                       f"the GPS climb agrees with the estimate's pitch: mounting pitch {deg:+.2f} deg (+- {se_deg:.2f}) "
                       "against extrinsic_rpy", evidence=ev)
    return None


def lean_verdict(tilt: TiltStats, imu: ImuSensor | None, min_updates: int = 50,
                 mount: MountYaw | None = None, grade: GradeFit | None = None) -> Verdict | None:
    """``mount``: the accelerometer's yaw fit; when it names a yaw error, the suggestion includes it.
    ``grade``: the GPS climb's fit of the mount's pitch, which the suggestion takes instead of the mean
    pitch (that holds the road's own grade too)."""
    if imu is None:
        return None
    means, stds, leaning = lean_of(tilt, min_updates)
    if not leaning:
        return None
    pitch = means[1] if grade is None else grade.delta
    rpy = full_mount(imu, (means[0], pitch), mount.delta if mount is not None and mount.named else 0.0)
    what = " and ".join(f"{('roll', 'pitch')[k]} {means[k]:+.3f} rad (std {stds[k]:.3f})" for k in leaning)
    if inverted_lean(tilt) is not None:
        return Verdict(imu.name, "attitude", "problem",
                       f"the estimate is upside down ({what} on average): the IMU is mounted upside down (its z axis "
                       "points down) and extrinsic_rpy does not say so. The pose published is upside down, and the "
                       "gyro's z rate reads against the wheels' yaw rate (a wheel yaw-rate fit of -1 x gyro is this, "
                       "not slip). The full mount is below",
                       sensor_key(imu.name, "extrinsic_rpy"), paste_mount(rpy),
                       {"lean_roll_rad": means[0], "lean_pitch_rad": means[1], "inverted": 1.0})
    return Verdict(imu.name, "attitude", "warn",
                   f"the robot leans by {what} on average: on level ground that is an IMU mounting rotation "
                   "missing from, or wrong in, extrinsic_rpy (the body-frame twist then climbs or sinks). The full "
                   "mount, both tilt axes composed with the configured one, is below",
                   sensor_key(imu.name, "extrinsic_rpy"), paste_mount(rpy),
                   {"lean_roll_rad": means[0], "lean_pitch_rad": means[1]})


def _altitude_reads(altitude: ChannelStats | None) -> str:
    """What the altitude's own channel shows of a climb its error state took: often nothing (the state absorbs
    it), or, once the height is off by more than the gate allows, fixes gated out."""
    if altitude is None or not altitude.n:
        return "and the altitude's innovations cannot show it"
    if altitude.rejected:
        return (f"and the altitude's fixes leave the gate as it does ({100 * altitude.rejected / altitude.n:.0f}% "
                "gated): not their noise, nor the gate")
    if altitude.verdict() == "ok":
        return "while the altitude's NIS looks normal"
    return f"and the altitude's NIS reads {altitude.verdict().removeprefix('nis_')} for it"


class Lean(BaseCheck):
    """The estimate's lean: against the grade the GPS altitude measures when there is enough driving to
    tell (it replaces "on level ground"), else its mean over the run. An estimate upside down is said first,
    GPS or not: the grade's chords measure a pitch of the IMU's mount and keep its roll, so their mount
    would leave the IMU upside down (an inverted car's height 37 m off, and 74 m with that line pasted)."""

    name = "lean"

    def run(self, ev: Evidence) -> list[Verdict]:
        altitude = ev.channels.get((ev.gps.name, "altitude")) if ev.gps is not None else None
        fit = grade_fit(ev.series, ev.config, altitude)
        if ev.tilt.n >= MIN_UPDATES and inverted_lean(ev.tilt) is not None:  # as lean_of asks of a lean
            return found(lean_verdict(ev.tilt, ev.run_imu, MIN_UPDATES, ev.mount, fit))
        graded = grade_verdict(fit, ev.run_imu, ev.mount, _pitch_learned(ev), altitude)
        return found(graded if graded is not None else lean_verdict(ev.tilt, ev.run_imu, MIN_UPDATES, ev.mount))
