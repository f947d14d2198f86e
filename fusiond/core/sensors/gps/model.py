"""GPS: position fixes in ENU at the datum; heading from a rigid fit of the first metres of travel.

Heading. A GPS measures where the antenna is, not where it points. Until travel has
shown the heading, the fix may move position only (channel ``position_unaligned``) and
the published heading variance says it is unknown (HEADING_UNKNOWN_SIGMA, rad). Every fix
since the first is paired with the dead-reckoned antenna position at its stamp; a
least-squares rigid fit (``estimator.rigid_fit``) of that track to the fixes gives the
heading correction and its uncertainty. Once that uncertainty is below
HEADING_PROVISIONAL_SIGMA the fit is applied: the state turns about the antenna (which the
fix has just put where the GPS says), so the position dead-reckoned along the wrong heading
since the previous fix turns with the heading, P turns with both, and the heading's
variance is re-set to the fit's. The fit keeps being refined with every fix (the stored
track turned with the state, so each new fit measures what is left) and re-applied until
its uncertainty is below HEADING_READY_SIGMA; then the heading is known and fixes become
ordinary, gated updates (channel ``position``). With a wandering receiver error modelled
(``error_tau_s``) the fit's uncertainty carries what the wander can bend the track by, which
more fixes do not average away on a small field (a mower's back-and-forth: the heading could
stay unfound for minutes, every fix fused unchecked, a multipath burst with them). Once the fit is
within HEADING_WANDER_READY_SIGMA there the fixes stay position-only updates but are gated
(channel ``position_provisional``). Full updates there were tried and lost: they teach the
wheel scale what a drive reading zero for seconds cost the dead-reckoning.

Altitude. Consumer receivers' altitude wanders by metres over minutes while they state
1-2 m; by default (``vertical_error_sigma``) the vertical carries a Gauss-Markov error state,
so the fixes pull z only as far as that wander and the odometry allow. A wander estimate its model refutes
(``_refuted_height``) is the vehicle's height instead: z takes it, and the twist's pitch held for this
(``pitch_estimation = "auto"``) is released. Altitudes gated out for seconds that agree with each other take
the height back, as a horizontal lock-out does (``_altitude_lost``): the height is then what is wrong.

Axes. A fix axis whose stated variance exceeds ``max_sigma``^2 is not measured and not
fused (a 2D receiver, or ``position_noise = [.., .., 1e6]`` to leave out altitude).

Steps. A receiver's error can step and stay (a re-acquisition, a multipath lock that ends): the fixes
jump by d from one epoch to the next and keep the new level. The gate rejects them as it rejects an
outlier, and waiting REACQUIRE_JUMP_S before believing them costs |d| for that long. Once the heading is
known, a run of gated-out fixes that began with a jump (its first fix the next fix after one the gate let in:
within JUMP_AFTER_S, or one and a half of the receiver's periods at a rate under 1/JUMP_AFTER_S) is judged by a sequential probability-ratio test of two hypotheses about fix k of the run, given
fixes 1..k-1 (``_step_llr``):
- H1, "the error stepped by one offset d": y_k ~ N(d_k, R_k + C_k + G_k), with d_k the R-weighted mean
  of the run's earlier innovations, C_k its covariance (sum R_j^-1)^-1, and G_k what the dead-reckoning
  added to the filter's own error H P H^T since the run began (the filter is not updated meanwhile);
- H0, "outliers / the old position": the fix is, with equal odds, an independent outlier of the run's
  size in any direction, y_k ~ N(0, S_k + m_k^2 I) with m_k^2 the run's mean squared innovation per axis,
  or an ordinary fix at the filter's position that the gate caught, y_k ~ N(0, S_k) (a gate set within
  the noise rejects runs of those); or, with probability BURST_REPEAT, a burst that repeats its offset
  (then distributed as under H1: a burst that holds one offset can not be told from a step until it
  ends, so this term is what makes it last).
With p1, p0 these densities, fix k adds lambda_k = log p1 - log((1 - rho) p0' + rho p1), rho =
BURST_REPEAT and p0' the independent-outlier density: lambda_k <= log(1 / rho) however well the fixes
agree, and negative when fix k lands farther from d_k than from the outliers' spread. The statistic is
Page's CUSUM, L_k = max(0, L_k-1 + lambda_k): at 0 the run starts over at the newest fix (it may be the
first of the new level). The step is taken when L_k >= log(1 / alpha), alpha = ``step_false_alarm``.
Threshold: the product of one-step predictive likelihood ratios is a non-negative martingale of mean 1
under H0 (each factor's H0-expectation is 1, whatever the earlier fixes estimated), so by Ville's
inequality P(it ever reaches 1 / alpha | H0) <= alpha: at most a fraction alpha of the runs (and
restarts) that are outliers as H0 describes them is taken for a step (Wald's bound for the open-ended test; Lorden's for the
CUSUM's mean run length, >= 1 / alpha tests). The cap sets the fewest fixes a step needs:
1 + ceil(log(1 / alpha) / log(1 / rho)), 6 at the defaults (5 agreeing increments of at most log 5 =
1.61 against log 1000 = 6.91): bursts of up to 5 fixes at one offset stay rejected whatever their
noise, and a 7 m step in 0.5 m fixes (each increment ~1.5) is taken at its 6th fix, 0.5 s at 10 Hz.
Taken, the state's horizontal position moves by the run's mean offset and its covariance grows by that
mean's (``_take_step``); the heading, the scales and their correlations stay: the receiver moved, not
the robot (the fix's record: channel position_step; the log line: gps_step_taken). A burst
that holds one offset for more than 5 fixes is taken so, and when it ends the fixes return to the
level it left: for REACQUIRE_JUMP_S after a step that level is a known hypothesis (``_back_llr``, no
offset to estimate, no cap), which one or two fixes decide at the same threshold. A run that did not
begin with a jump (the filter drifting off through a gap, a wrong heading)
keeps the REACQUIRE_S rule with its new heading search, and so does a run while the heading is only
provisional (its dead-reckoned track may bend by what the heading is not sure of).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import msgspec
import numpy as np

from .... import reasons
from ....estimator import POSITION_ROWS, YAW_ROW, mat3
from ....estimator import observations as obs
from ....estimator.geodesy import EnuFrame
from ....estimator.rigid_fit import RigidFit, fit_rigid
from ....logs import get_logger
from ...diagnostics import DiagnosticsRecord, chi2_ppf
from ..base import SensorContext, SensorModel
from ..checks import Rejected, finite
from ..frame import lever, new_frame, set_position
from .sample import GpsSample
from .table import GpsSensor

if TYPE_CHECKING:
    from ..state import FilterState

log = get_logger("fusiond.core")


HEADING_MIN_TRAVEL = 0.3  # dead-reckoned / GPS extent below this: pushed, slipping or GPS wander, start over
HEADING_UNKNOWN_SIGMA = math.pi / math.sqrt(3.0)  # std dev of a heading uniform on the circle, rad
HEADING_PROVISIONAL_SIGMA = 0.3  # rad: apply the rigid fit provisionally (fixes still move position only)
HEADING_READY_SIGMA = 0.05  # rad: the heading is known, fixes become full (gated) updates
HEADING_WANDER_READY_SIGMA = 0.15  # rad: beside a modelled receiver wander (module doc), the position-only
# fixes are gated from here: the dead-reckoning between fixes along a heading this good is off by 15 % of
# a fix's travel at most, far inside the gate
HEADING_MAX_FIXES = 400  # fixes kept for the fit; beyond, every other one is dropped (the extent stays)
REACQUIRE_S = 3.0  # s of consecutive gated-out fixes ...
REACQUIRE_FIXES = 5  # ... and at least this many, agreeing with each other: the filter is what is wrong
REACQUIRE_AGREE = 0.1  # "agreeing": spread of their innovations within this fraction of the innovation ...
REACQUIRE_SIGMAS = 3.0  # ... or within this many fix sigmas
REACQUIRE_JUMP_S = 10.0  # s instead of REACQUIRE_S when the run began with a jump of the fixes (``_locked_out``)
JUMP_AFTER_S = 1.0  # ... "a jump": its first fix within this of an accepted one, and most of its offset new
JUMP_AFTER_PERIODS = 1.5  # ... or within this many fix periods (a slow receiver's next fix; a missed one makes 2)
BURST_REPEAT = 0.2  # the outlier model's statement: a burst repeats its previous fix's offset with this probability
# per fix. It caps what one agreeing fix can say for a step at log(1 / BURST_REPEAT) (module doc, "Steps")
FROZEN_MIN_TRAVEL = 0.05  # m of dead-reckoned travel after which a bit-identical repeated fix is a frozen receiver
FROZEN_JITTER = 0.01  # m: a fix this close to the one a repeat began with is that fix again, with rounding noise ...
FROZEN_JITTER_TRAVEL = 0.5  # ... once the wheels have moved this far (m) since it came: a frozen receiver too
NOISE_UPPER_Z = 2.0  # the measured unstated noise is used at its ~98 % upper bound (one-sided, z = 2 sigmas)
ENU_NAMES = ("east", "north", "up")
WHEEL_SCALE = "wheel_scale"  # the state block of the odometry's speed scale (estimator/scale.py)
# The altitude's wander state refuted: its estimate b of a zero-mean Gauss-Markov error of stationary variance
# sigma^2 has a variance below sigma^2, so b^2 / sigma^2 beyond the chi-square(1) quantile of 1 - this happens
# under the model less often than this per fix (``_refuted_height``)
HEIGHT_REFUTED_FALSE_ALARM = 1e-6
_ZERO3 = (0.0, 0.0, 0.0)


class GpsTrack(msgspec.Struct, frozen=True, gc=False):
    """What the GPS keeps between fixes (immutable: shared by history snapshots): while the heading
    is unknown, the fixes paired with the dead-reckoned antenna position at their stamps; always,
    the newest coordinates, to recognise a frozen receiver. ``base`` + the state's ``travel`` is
    the dead-reckoned base position. A Struct, as ``GpsOwn``: each fix replaces it, and a dataclass's
    ``replace`` costs a fix more than its position update."""

    points: tuple[tuple[float, float, float, float, float], ...]  # (gx, gy, dx, dy, weight)
    base: tuple[float, float, float]
    first: tuple[float, float]  # the first fix
    applied: bool = False  # a provisional fit has been applied
    extent: float = 0.0  # farthest fix from the first so far, m (a loop back to the start keeps it)
    t0: float = 0.0  # stamp of the first fix
    last_lla: tuple[float, float, float] | None = None  # the newest fix's coordinates, as received ...
    last_dr: tuple[float, float] = (0.0, 0.0)  # ... and the dead-reckoned base position when they first came
    last_enu: tuple[float, float] | None = None  # ... and their east/north (the repeat-with-noise check)
    rest: float | None = None  # the standstill (its ``still_since``) the newest point was taken in; None: moving
    guess: tuple[float, float] | None = None  # before a fit is applied: the newest fit's (theta, var_theta)


@dataclass(frozen=True, slots=True)
class HeldForHeight:
    """What ``GpsModel._refuted_height`` needs: the error rows held (no variance) until the altitude's wander is
    refuted and the priors they get then, the wander's vertical component (nominal, error index) and its
    stationary variance, and the bound on its estimate squared."""

    rows: list[int]
    priors: list[float]
    b_nominal: int
    b_error: int
    var: float
    bound: float


@dataclass(slots=True)
class GpsInput:
    """A valid fix: WGS84 position and its ENU covariance (row-major 9-tuple, m^2). ``stated``: False
    when the covariance is the unknown default (the receiver said nothing, and no position_noise)."""

    lla: tuple[float, float, float]
    cov: tuple[float, ...]
    stated: bool = True


class GpsPolicy:
    """NavSatFix: skip fixes without a fix (status < 0, or latitude and longitude both exactly 0:
    a driver's placeholder), take the noise from the message covariance (floored), the config's
    ``position_noise``, or a conservative default when the receiver says its covariance is
    unknown or states none (all zeros: no receiver is exact, so the zeros are not a statement)."""

    def __init__(self, cfg: GpsSensor) -> None:
        self.cfg = cfg
        self._floor = cfg.position_min_sigma**2
        self._override = None if cfg.position_noise is None else mat3.diag(*[v * v for v in cfg.position_noise])
        self._unknown = mat3.diag(*[v * v for v in cfg.unknown_position_sigma])

    def convert(self, s: GpsSample) -> GpsInput:
        if s.status < 0:
            raise Rejected(reasons.NO_FIX, f"status {s.status}")
        lla = (s.latitude, s.longitude, s.altitude)
        if not finite(lla):
            raise Rejected(reasons.NON_FINITE, "latitude/longitude/altitude")
        if not (-90.0 <= s.latitude <= 90.0 and -180.0 <= s.longitude <= 180.0 and -1e5 < s.altitude < 1e6):
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "latitude/longitude/altitude out of range")
        if s.latitude == 0.0 and s.longitude == 0.0:
            # a driver's placeholder for "no fix" under a fix status: no receiver reads exactly 0/0
            raise Rejected(reasons.NO_FIX, "latitude and longitude exactly 0")
        if self._override is not None:
            return GpsInput(lla, self._override)
        if s.covariance_type == 0:
            return GpsInput(lla, self._unknown, False)
        c = s.position_covariance
        if len(c) != 9 or not finite(c):
            raise Rejected(reasons.BAD_COVARIANCE, "position covariance must be 9 finite numbers")
        if c[0] < 0.0 or c[4] < 0.0 or c[8] < 0.0:
            raise Rejected(reasons.NEGATIVE_COVARIANCE, "position")
        if c[0] == 0.0 and c[4] == 0.0 and c[8] == 0.0:
            # no receiver is exact on every axis: a driver that did not fill the covariance in (or
            # lost the fix and says so with zeros) states nothing, as covariance_type UNKNOWN
            return GpsInput(lla, self._unknown, False)
        if s.covariance_type == 2:  # COVARIANCE_TYPE_DIAGONAL_KNOWN: off-diagonals are not meaningful
            c = mat3.diag(c[0], c[4], c[8])
        f = self._floor
        cov = (max(c[0], f), c[1], c[2], c[3], max(c[4], f), c[5], c[6], c[7], max(c[8], f))
        return GpsInput(lla, cov)




class StepRun(msgspec.Struct, frozen=True, gc=False):
    """The step test's sums over the run since its (re)start (module doc, "Steps"): the innovations'
    information ``info`` = sum R^-1 and ``info_y`` = sum R^-1 y (row-major 2x2 and 2), their squared norms
    ``sq`` over ``n`` fixes, H P H^T at the run's first fix ``hp0``, and the CUSUM ``llr``."""

    n: int
    info: tuple[float, float, float, float]
    info_y: tuple[float, float]
    sq: float
    hp0: tuple[float, float, float, float]
    llr: float = 0.0
    back: float = 0.0  # the CUSUM of "back at the level the last step left" (``_back_llr``)


class GpsOwn(msgspec.Struct, frozen=True, gc=False):
    """The GPS's slice of the filter state (immutable: history snapshots share it)."""

    track: GpsTrack | None = None  # the fixes since the first one (heading search, frozen-receiver check)
    travel: tuple[float, float, float] = _ZERO3  # dead-reckoned base motion since the track's base
    # consecutive gated-out fixes: (t, innovation east, north, variance, fix east, north, dead-reckoned east, north)
    rejected: tuple[tuple[float, float, float, float, float, float, float, float], ...] = ()
    accepted: tuple[float, float, float] | None = None  # the newest fix the gate let in: (t, innovation east, north)
    step: StepRun | None = None  # the step test over a run of gated-out fixes that began with a jump (module doc)
    left: tuple[float, float, float] | None = None  # the last step taken: (t, east, north), the level it left
    unaligned: float = 0.0  # m dead-reckoned since the last fix (they share one heading error)
    # unstated noise (``_measured_noise``): consecutive fixes' distances against the dead-reckoned ones,
    # (count, sum of squared differences), and the previous fix: (t, east, north, dead-reckoned east, north)
    increments: tuple[int, float] = (0, 0.0)
    last: tuple[float, ...] | None = None
    # the state's horizontal position after the newest fix applied (``shown_position``)
    anchor: tuple[float, float] | None = None
    # the altitude's (``_altitude_lost``): the newest the gate let in (t, innovation), and the run gated out
    # since: (first t, fixes, sum of innovations, of their squares, largest variance, began with a jump)
    up_accepted: tuple[float, float] | None = None
    up_rejected: tuple[float, int, float, float, float, bool] | None = None


class GpsModel(SensorModel):
    config_type = GpsSensor
    sample_type = GpsSample
    policy_type = GpsPolicy
    predicts = True  # accumulates the dead-reckoned travel between fixes
    shows_position = True  # publishes the expected position while the heading is searched for
    unmeasured = frozenset({"position_frozen"})  # a frozen receiver's repeat (``_frozen``)

    def __init__(self, cfg: GpsSensor, index: int, ctx: SensorContext) -> None:
        super().__init__(cfg, index, ctx)
        layout = ctx.layout
        self.error = "gps_error" if layout.has("gps_error") else None
        self._said_ready = False  # "gps_heading_initialised" logged for the current search (``_apply_fit``)
        self._error_rows = None
        if self.error is not None:
            e = layout.error["gps_error"]
            self._error_rows = list(range(e.start, e.stop))
        # variance of the receiver's slowly wandering horizontal error (the Gauss-Markov state's prior)
        self.wander = 0.0
        if cfg.error_tau_s > 0.0 and cfg.error_sigma is not None:
            self.wander = max(cfg.error_sigma[0], cfg.error_sigma[1]) ** 2
        # An IMU's absolute yaw trusted as the heading in ENU (no offset estimated): no heading search.
        self.yaw_given = ctx.absolute_yaw and not layout.has("yaw_offset")
        # the wheels' scale in the state: a locked-out run may be the track stretched (``_locked_out``)
        self._scaled = layout.has(WHEEL_SCALE)
        # blocks held until the height the wander state takes is refuted (``_refuted_height``): (rows, prior)
        held = [(list(range(layout.error[b.name].start, layout.error[b.name].stop)), b.release_sigma)
                for b in layout.blocks if getattr(b, "release_sigma", 0.0) > 0.0]
        self._held: HeldForHeight | None = None
        if held and self.error is not None:
            block = next(b for b in layout.blocks if b.name == "gps_error")
            if block.sigma[2] > 0.0:
                var = block.sigma[2] ** 2
                self._held = HeldForHeight([i for rows, _ in held for i in rows], [p for rows, p in held for _ in rows],
                                           layout.nominal["gps_error"].start + 2, self._error_rows[2], var,
                                           var * chi2_ppf(1.0 - HEIGHT_REFUTED_FALSE_ALARM, 1.0))

    def on_start(self, s: "FilterState") -> None:
        """A fresh state: the ENU frame at the configured datum (or none yet), heading unknown."""
        s.enu = EnuFrame(*self.cfg.datum) if self.cfg.datum is not None else None
        s.heading_ready = False
        s.own[self.index] = GpsOwn()

    def on_predict(self, s: "FilterState", x0: np.ndarray, x1: np.ndarray) -> tuple[float, float, float] | None:
        """While a track is kept, accumulate the dead-reckoned motion of each prediction, and return
        what the linearised motion model leaves out of its covariance.

        A displacement D driven along a heading whose error is psi ~ N(0, s2) is off by D (R(psi) - I):
        across the heading by D sin(psi), which the linearised model has (D^2 s2), and along it by
        D (cos(psi) - 1), which it drops: E(1 - cos psi)^2 = 3/2 - 2 exp(-s2/2) + exp(-2 s2)/2, about
        s2^2/2 (nothing) once the heading is known, but ~1.1 of D^2 while it is unknown (sigma ~pi/sqrt 3),
        where the filter would otherwise claim metres of confidence along a track driven the wrong way.
        The steps since the last fix share that heading error, so their lengths add before squaring:
        each step adds var(D + d) - var(D) along its direction of travel; a fix resets D."""
        own: GpsOwn = s.own[self.index]
        if own.track is None:
            return None
        tr, unaligned = own.travel, own.unaligned
        e0, n0, u0 = x0[:3].tolist()  # the positions as floats: one slice each (a third of three items' cost)
        e1, n1, u1 = x1[:3].tolist()
        dx, dy = e1 - e0, n1 - n0
        d = math.hypot(dx, dy)
        s.own[self.index] = msgspec.structs.replace(own, travel=(tr[0] + dx, tr[1] + dy, tr[2] + (u1 - u0)),
                                                    unaligned=unaligned + d)
        if d == 0.0:
            return None
        s2 = s.ekf.yaw_variance()
        along = 1.5 - 2.0 * math.exp(-0.5 * s2) + 0.5 * math.exp(-2.0 * s2)
        var = along * ((unaligned + d) ** 2 - unaligned**2)
        ux, uy = dx / d, dy / d
        return var * ux * ux, var * ux * uy, var * uy * uy

    def shown_origin(self, s: "FilterState") -> tuple[float, float] | None:
        """The state's position after the newest fix while the heading is searched for (``anchor``)."""
        return None if s.heading_ready else s.own[self.index].anchor

    def shown_position(self, s: "FilterState") -> tuple[float, float] | None:
        """While the heading is searched for, the expected position: the state dead-reckons from the
        newest fix along a placeholder heading whose error psi is as wide as the filter's yaw variance
        s2 (pi/sqrt 3 while unknown), and the mean of a displacement D turned by psi ~ N(0, s2) is
        E[R(psi)] D = exp(-s2/2) D. So the published position moves from that fix by a fifth of the
        dead-reckoning while nothing is known of the heading (a car doing 20 m/s north is not
        published driving east), and by all of it as the fits narrow the heading. Before a fit is applied
        (the track is shorter than heading_init_m) the fixes so far are fitted already, psi ~ N(theta,
        var_theta) where that is narrower: the displacement turns by theta and shrinks by exp(-var_theta/2)
        (``GpsTrack.guess``): a car starting at 19 m/s is published where it goes from its second fix on,
        not half a metre behind it at each. None (the state's position) once the heading is known."""
        if s.heading_ready:
            return None
        own = s.own[self.index]
        anchor = own.anchor
        if anchor is None:
            return None
        p = s.ekf.position()
        ex, ey = p[0] - anchor[0], p[1] - anchor[1]
        var = s.ekf.yaw_variance()
        guess = own.track.guess if own.track is not None else None
        if guess is not None and guess[1] < var:
            # the fixes so far, fitted before any fit is applied: the heading's error psi ~ N(theta, var_theta)
            # about the placeholder, and E[R(psi)] D = exp(-var_theta/2) R(theta) D
            theta, var = guess
            c, sn = math.cos(theta), math.sin(theta)
            ex, ey = c * ex - sn * ey, sn * ex + c * ey
        k = math.exp(-0.5 * var)
        return anchor[0] + k * ex, anchor[1] + k * ey

    def apply(self, s: "FilterState", inp: GpsInput, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        cfg = self.cfg
        if s.enu is None:
            s.enu = EnuFrame(*inp.lla)  # no datum configured: the first valid fix (in stamp order)
        z = s.enu.enu(*inp.lla)
        ekf = s.ekf
        rows = measured_axes(cfg, inp.cov)
        if self.ctx.two_d:  # altitude is not fused: z is held at 0
            rows = tuple(r for r in rows if r != 2)
        if not s.frame_ready:
            self._first_fix(s, z, inp, rows, stamp, emit)
            return []
        if s.own[self.index].track is None:
            # The world frame is defined but this GPS keeps no track (set_pose restarted it): start
            # one at this fix, and look for the heading again if it is not known.
            self._start_track(s, z, inp.lla, stamp)
            if not s.heading_ready:
                self._heading(s, z, inp.cov, stamp, emit)
        if self._frozen(s, inp.lla, z):
            # A receiver repeating its last fix with a new stamp while the wheels moved: not a measurement.
            if not emit:
                return []
            return [self.record(stamp, [ENU_NAMES[i] for i in rows], [0.0] * len(rows),
                                [inp.cov[4 * i] for i in rows], 0.0, len(rows), True, "position_frozen", late)]
        if not inp.stated and cfg.estimate_unknown_noise:
            inp = self._measured_noise(s, z, inp, stamp)
        if not rows:
            return []
        horizontal = tuple(r for r in rows if r < 2)
        vertical = tuple(r for r in rows if r == 2)
        if s.heading_ready:
            threshold, mask, channel = cfg.mahalanobis_threshold, None, "position"
        else:
            # Heading unknown: the fix may move position only, and is not gated (a dead-reckoned
            # track along a wrong heading must not lock the filter out of the GPS), unless beside a
            # modelled wander the fit is already within HEADING_WANDER_READY_SIGMA (module doc). A
            # Gauss-Markov GPS error is a "consider" state here: its variance widens S (H has its
            # columns) but the offset a wrong heading builds up must not be absorbed into it as GPS error.
            gated = self.wander > 0.0 and ekf.yaw_variance() <= HEADING_WANDER_READY_SIGMA**2
            threshold = cfg.mahalanobis_threshold if gated else math.inf
            mask = self.ctx.position_mask
            channel = "position_provisional" if gated else "position_unaligned"
        records: list[DiagnosticsRecord] = []
        # The horizontal and the vertical of a fix are two measurement blocks, each gated on its own:
        # a consumer receiver's altitude wanders by metres that say nothing about its east and north,
        # and one 3-dof test would throw good horizontal fixes away with a bad altitude.
        if horizontal:
            if mask is None:
                y, H, R = self._block(ekf, z, inp.cov, horizontal)
            else:  # the antenna about the base along a heading not known yet (``_unaligned_lever``)
                lever_mean, spread = self._unaligned_lever(ekf.yaw_variance())
                y, H, R = self._block(ekf, z, inp.cov, horizontal, lever_mean)
                if spread > 0.0:
                    H[:, YAW_ROW] = 0.0
                    R[np.diag_indices_from(R)] += spread
            res = ekf.update(y, H, R, threshold, mask)
            own = s.own[self.index]
            if own.unaligned and not res.rejected:  # the fix bounds the displacement again
                s.own[self.index] = msgspec.structs.replace(own, unaligned=0.0)
            if channel != "position_unaligned":
                lost = self._locked_out(s, res.rejected, y, R, z, stamp)
                step = None
                if not lost and channel == "position" and len(horizontal) == 2:
                    step = self._step_test(s, res.rejected, y, H, R)
                if step is not None:
                    self._take_step(s, step, stamp, emit)
                    channel = "position_step"  # the receiver moved, not the robot: the doctor tells the two apart
                elif lost:
                    self._reacquire(s, z, inp, horizontal, stamp, emit)
                    channel = "position_reacquired"
            if channel == "position_unaligned" or (channel == "position_provisional" and not res.rejected):
                if not res.rejected:
                    self._heading(s, z, inp.cov, stamp, emit)  # after the fix has put the antenna where it is
            if not res.rejected and not s.heading_ready:
                p = ekf.position()
                s.own[self.index] = msgspec.structs.replace(s.own[self.index], anchor=(p[0], p[1]))
            if emit:
                # While the heading is unknown, the innovation carries the dead-reckoning along a wrong
                # heading: its NIS tests the heading search, not the receiver's noise (learning); so
                # does the fix that re-acquired a locked-out filter.
                records.append(self.record(stamp, [ENU_NAMES[i] for i in horizontal], y.tolist(), res.innovation_var,
                                           res.nis, len(horizontal), res.rejected, channel, late,
                                           learning=channel != "position"))
        if vertical:
            y, H, R = self._block(ekf, z, inp.cov, vertical)
            # The altitude does not depend on the heading: gated as soon as a gate is configured.
            res = ekf.update(y, H, R, cfg.mahalanobis_threshold, mask)
            if self._held is not None and not res.rejected:
                self._refuted_height(s, stamp, emit)
            self._altitude_lost(s, res.rejected, float(y[0]), float(R[0, 0]), stamp, emit)
            if emit:
                records.append(self.record(stamp, ["up"], y.tolist(), res.innovation_var, res.nis, 1, res.rejected,
                                           "altitude", late))
        return records

    def _refuted_height(self, s: "FilterState", stamp: float, emit: bool, force: bool = False) -> None:
        """The altitude's wander state holding a height its model refutes: the climb is the vehicle's.

        The wander b is a zero-mean Gauss-Markov error of stationary std dev sigma (vertical_error_sigma): the
        filter's estimate of it has a variance below sigma^2, so b^2 > sigma^2 chi2(1 - HEIGHT_REFUTED_FALSE_ALARM)
        (4.9 sigma) happens under that model at fewer than one fix in a million. What puts it there is a height the
        motion model makes and the fixes do not: a twist that climbs as the body is pitched against the wheels (an
        IMU pitched in its mount, 7 m per 100 m at 4 deg, which b takes for receiver wander until the published
        height leaves the fixes by tens of metres). Then the height b holds is the state's (z takes it: z + b, what
        the fixes measure, is unchanged), b starts again from its prior, and the blocks held for this (the twist's
        pitch, ``pitch_estimation = "auto"``) get their priors: the climb is learned from the next fixes on. Once:
        a released block is no longer held (its variance is no longer 0). ``force``: refuted by the altitude's
        lock-out (``_altitude_lost``) whatever b holds."""
        ekf, held = s.ekf, self._held
        P = ekf.P
        if any(P[i, i] != 0.0 for i in held.rows):
            return  # released already
        b = float(ekf.x[held.b_nominal])
        if b * b <= held.bound and not force:
            return
        ekf.reattribute((held.b_nominal, held.b_error), (2, 2), held.var,
                        (held.rows, np.diag([p * p for p in held.priors])))
        if emit:
            why = ("the fixes' altitude gated out for seconds, agreeing" if force else
                   "the altitude's wander state held beyond its model")
            log.warning("height_refuted", sensor=self.cfg.name, stamp=stamp, wander_m=b, sigma_m=math.sqrt(held.var),
                        reason=why + ": the height is the vehicle's (a twist climbing with the body pitched in its "
                                     "mount); what was held for this (the twist's pitch, pitch_estimation = "
                                     "\"auto\") is estimated from here on")

    def _altitude_lost(self, s: "FilterState", rejected: bool, y: float, r: float, stamp: float, emit: bool) -> None:
        """Is the filter locked out of the altitude? As for the horizontal (``_locked_out``): altitudes gated out
        for REACQUIRE_S in a row (REACQUIRE_JUMP_S when the run began with a jump of the fixes: a receiver's
        height reference switching), at least REACQUIRE_FIXES of them, whose innovations agree (their spread
        within REACQUIRE_AGREE of their mean or REACQUIRE_SIGMAS of the fixes' sigma) say the filter's height is
        what is wrong: a height the motion model made while no fix came (a tunnel, with the twist climbing as a
        pitched IMU tilts it) that no later fix can pull back once it is beyond the gate. The height is then
        taken from the fixes: a wander the state held beyond its model is z's (``_refuted_height``), and z's
        variance opens by the run's mean innovation squared, so that the next altitude is let in. A run that
        does not agree starts again at its newest fix."""
        own: GpsOwn = s.own[self.index]
        if not rejected:
            s.own[self.index] = msgspec.structs.replace(own, up_accepted=(stamp, y), up_rejected=None)
            return
        run = own.up_rejected
        if run is None:
            run = (stamp, 0, 0.0, 0.0, 0.0, _jumped(own.up_accepted, (stamp, y), self._jump_after(s)))
        t0, n, sy, syy, rmax, jumped = run
        n, sy, syy, rmax = n + 1, sy + y, syy + y * y, max(rmax, r)
        wait = REACQUIRE_JUMP_S if jumped else REACQUIRE_S
        if n < REACQUIRE_FIXES or stamp - t0 < wait:
            s.own[self.index] = msgspec.structs.replace(own, up_rejected=(t0, n, sy, syy, rmax, jumped))
            return
        mean = sy / n
        spread = math.sqrt(max(syy / n - mean * mean, 0.0))
        if spread > max(REACQUIRE_AGREE * abs(mean), REACQUIRE_SIGMAS * math.sqrt(rmax)):
            s.own[self.index] = msgspec.structs.replace(own, up_rejected=(stamp, 1, y, y * y, r, False))
            return
        s.own[self.index] = msgspec.structs.replace(own, up_rejected=None)
        ekf = s.ekf
        if self._held is not None:
            self._refuted_height(s, stamp, emit, force=True)
        ekf.widen([POSITION_ROWS[2]], np.array([[mean * mean]]))
        if emit:
            log.warning("gps_altitude_reacquired", sensor=self.name, stamp=stamp, rejected=n, seconds=stamp - t0,
                        offset_m=mean)

    def _measured_noise(self, s: "FilterState", z, inp: GpsInput, stamp: float) -> GpsInput:
        """A receiver that states no accuracy: its horizontal white noise, measured. Between two consecutive
        fixes (within the sensor's timeout) the wheels know how far the antenna went far better than a fix
        knows where it is, and a distance needs no heading (this works while the heading is searched for):
        d = |z_k - z_k-1| - |dr_k - dr_k-1| is the difference of the two fixes' noises along the direction
        of travel, E d^2 = 2 sigma^2, plus what a wheel scale error and a wandering receiver error add over
        one interval (at rest, the noise's full horizontal norm): the estimate errs large, never small. It
        is used below the unknown default only, at the upper end of its own uncertainty (``_upper_variance``),
        floored by position_min_sigma. The sums live in the state's slice: a late fix re-applied counts
        once. The altitude keeps the default and its wander state."""
        own: GpsOwn = s.own[self.index]
        t, b = own.travel, own.track.base
        dr = (b[0] + t[0], b[1] + t[1])
        n, sq = own.increments
        prev = own.last
        if prev is not None and 0.0 < stamp - prev[0] <= self.cfg.timeout_s:
            d = math.hypot(z[0] - prev[1], z[1] - prev[2]) - math.hypot(dr[0] - prev[3], dr[1] - prev[4])
            n, sq = n + 1, sq + d * d
        s.own[self.index] = msgspec.structs.replace(own, increments=(n, sq), last=(stamp, z[0], z[1], *dr))
        upper = _upper_variance(sq, n)
        if upper is None:
            return inp
        var = max(self.cfg.position_min_sigma**2, upper)
        c = inp.cov
        if var >= c[0] and var >= c[4]:
            return inp
        return GpsInput(inp.lla, (min(c[0], var), 0.0, 0.0, 0.0, min(c[4], var), 0.0, 0.0, 0.0, c[8]), False)

    def _block(self, ekf, z, cov, rows: tuple[int, ...],
               lever_xyz: tuple[float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fix's rows ``rows`` (east north up indices) as a measurement of the state now (the antenna at
        ``lever_xyz`` in base_link; default: extrinsic_xyz)."""
        lever_xyz = self.cfg.extrinsic_xyz if lever_xyz is None else lever_xyz
        y, H, R = obs.position(self.ctx.layout, ekf.x, z, cov, lever_xyz, self.error)
        if len(rows) == 3:
            return y, H, R
        lo, hi = rows[0], rows[-1] + 1
        if hi - lo == len(rows):  # the horizontal pair, the altitude: slices, cheaper than the fancy picks below
            return y[lo:hi], H[lo:hi], R[lo:hi, lo:hi].copy()  # a block of R is strided: copied in C order
        idx = list(rows)
        # np.ix_ costs more than the update it feeds; the column pick leaves R in Fortran order, which the
        # compiled update refuses (BufferError: the Python reference would run it): copied in C order
        return y[idx], H[idx], R[idx][:, idx].copy()

    def _first_fix(self, s: "FilterState", z, inp: GpsInput, rows: tuple[int, ...], stamp: float,
                   emit: bool) -> None:
        """The first fix defines the world frame: the base goes where it says, heading unknown
        (unless an absolute IMU yaw is trusted as ENU heading)."""
        ekf = s.ekf
        self._set_from_fix(s, z, inp.cov, rows)
        split = POSITION_ROWS
        if self.cfg.datum is None and 2 in rows:
            # The datum's altitude is this fix's: the frame's zero height is where the antenna is
            # now, exactly, whatever this fix's own error. (With a configured datum the first
            # altitude is as uncertain as the fix, slow error included.)
            ekf.reset_covariance([POSITION_ROWS[2]], np.zeros((1, 1)))
            split = (0, 1)
        if self.error is not None:
            self._split_first_fix(s, split)
        s.frame_ready = True
        new_frame(s)
        self._start_track(s, z, inp.lla, stamp)
        if self.yaw_given:
            s.heading_ready = True
        else:
            ekf.reset_covariance([YAW_ROW], np.array([[HEADING_UNKNOWN_SIGMA**2]]))
            self._heading(s, z, inp.cov, stamp, emit)

    def _locked_out(self, s: "FilterState", rejected: bool, y: np.ndarray, R: np.ndarray, z, stamp: float) -> bool:
        """Is the filter locked out of the GPS? A gate protects against outliers, but once the
        estimate is far off (a gap longer than its covariance allows, a wrong heading) every fix
        is an "outlier" and the gate never lets the truth back in. Fixes rejected for
        REACQUIRE_S in a row (at least REACQUIRE_FIXES) that agree with each other and moved with
        the wheels say so. "Agree": the fixes are the dead-reckoned track turned and shifted (one
        rotation and one offset fitted, and a stretch where the wheels' scale is in the state:
        ``_fitted_residual``), to within the fixes' noise or a tenth of the offset: a filter off by a constant offset, or driving along a wrong heading, whose error
        grows with the distance, not a multipath burst whose error jumps around the track. A
        receiver that lost its fix and repeats it with a little noise (its covariance then as
        unknown, wide enough for the growing innovations to "agree") stays where it was while the
        wheels drive on (a car at 28 m/s would be pulled back hundreds of metres): no evidence that
        the filter is wrong. Wheels spinning on the spot look the same until the robot moves again."""
        own: GpsOwn = s.own[self.index]
        if not rejected:
            s.own[self.index] = msgspec.structs.replace(own, rejected=(), accepted=(stamp, float(y[0]), float(y[1])))
            return False
        t = own.travel
        dr = (own.track.base[0] + t[0], own.track.base[1] + t[1])
        run = own.rejected + ((stamp, float(y[0]), float(y[1]), float(max(R[0, 0], R[1, 1])), z[0], z[1], *dr),)
        s.own[self.index] = msgspec.structs.replace(own, rejected=run)
        if len(run) < REACQUIRE_FIXES or stamp - run[0][0] < self._reacquire_after(own, run[0], self._jump_after(s)):
            return False
        me, mn = sum(r[1] for r in run) / len(run), sum(r[2] for r in run) / len(run)
        # with the wheels' scale in the state, the track may be stretched too (a tyre changed, a speed 20 %
        # high from one moment: every fix gated out for good, 97 m off, where the fit's rotation alone left 10 m)
        spread, _ = _fitted_residual([(r[4], r[5]) for r in run], [(r[6], r[7]) for r in run], self._scaled)
        noise = REACQUIRE_SIGMAS * math.sqrt(max(r[3] for r in run))
        allowed = max(REACQUIRE_AGREE * math.hypot(me, mn), noise)
        first, last = run[0], run[-1]
        wheels = math.hypot(last[6] - first[6], last[7] - first[7])
        fixes = math.hypot(last[4] - first[4], last[5] - first[5])
        if spread > allowed or (wheels > noise and fixes < HEADING_MIN_TRAVEL * wheels):
            s.own[self.index] = msgspec.structs.replace(own, rejected=run[1:])  # slide: keep looking
            return False
        return True

    def _step_test(self, s: "FilterState", rejected: bool, y: np.ndarray, H: np.ndarray,
                   R: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The step test (module doc, "Steps") after this fix's horizontal update: started at the first
        gated-out fix of a run that began with a jump, fed every further one, dropped at an accepted fix.
        The step (d, C) once the CUSUM reaches log(1 / step_false_alarm), else None."""
        own: GpsOwn = s.own[self.index]
        alpha = self.cfg.step_false_alarm
        if not rejected or alpha <= 0.0:
            if own.step is not None:
                s.own[self.index] = msgspec.structs.replace(own, step=None)
            return None
        hp = H.dot(s.ekf.P).dot(H.T)
        st = own.step
        left = own.left
        if left is not None and own.rejected and own.rejected[0][0] - left[0] > REACQUIRE_JUMP_S:
            left = None  # long enough at the new level: a return is a step like any other
        h = -math.log(alpha)
        if st is None:
            if len(own.rejected) != 1 or not _jumped(own.accepted, own.rejected[0][:3], self._jump_after(s)):
                return None  # not the first fix of a run, or no jump: the REACQUIRE_S rule alone
            st = _step_start(y, R, hp)
        else:
            llr = st.llr + _step_llr(st, y, R, hp)
            if llr <= 0.0:  # the run so far does not hold one offset: start over at this fix
                st = msgspec.structs.replace(_step_start(y, R, hp), back=st.back)
            else:
                Ri = np.linalg.inv(R)
                i0, i1, i2, i3 = (Ri + np.array(st.info).reshape(2, 2)).ravel().tolist()
                iy = Ri.dot(y) + np.array(st.info_y)
                st = StepRun(st.n + 1, (i0, i1, i2, i3), (float(iy[0]), float(iy[1])), st.sq + float(y.dot(y)),
                             st.hp0, llr, st.back)
        if left is not None:
            st = msgspec.structs.replace(st, back=max(0.0, st.back + _back_llr(st, y, R, hp, left)))
        s.own[self.index] = msgspec.structs.replace(own, step=st, left=left)
        if st.llr < h and st.back < h:
            return None
        C = np.linalg.inv(np.array(st.info).reshape(2, 2))
        return C.dot(np.array(st.info_y)), C

    def _take_step(self, s: "FilterState", step: tuple[np.ndarray, np.ndarray], stamp: float, emit: bool) -> None:
        """The receiver's error stepped by d (module doc, "Steps"): the horizontal position moves by d, the
        run's mean offset, and its covariance grows by C, that mean's own; what P says about the heading,
        the scales and their relation to the position stays (a constant shift changes none of it). The
        newest fix, at the new level, becomes the reference of the next jump check."""
        d, C = step
        own: GpsOwn = s.own[self.index]
        ekf = s.ekf
        if emit:  # once: not again for each re-application after a late sample
            log.warning("gps_step_taken", sensor=self.name, stamp=stamp, fixes=own.step.n,
                        seconds=stamp - own.rejected[0][0] if own.rejected else 0.0,
                        east=float(d[0]), north=float(d[1]), llr=own.step.llr)
        p = ekf.position()
        ekf.set_position((p[0] + float(d[0]), p[1] + float(d[1]), p[2]), (0, 1))
        ekf.widen(list(POSITION_ROWS[0:2]), C)
        new_frame(s)  # the position moved under the differential pose sensors: their deltas restart
        last = own.rejected[-1] if own.rejected else None
        accepted = None if last is None else (stamp, last[1] - float(d[0]), last[2] - float(d[1]))
        back = own.left is not None and own.step.back >= own.step.llr
        left = None if back else (stamp, float(d[0]), float(d[1]))
        s.own[self.index] = msgspec.structs.replace(own, rejected=(), step=None, accepted=accepted, left=left)

    def _jump_after(self, s: "FilterState") -> float:
        """How soon after an accepted fix a gated-out one is the next fix, not the first after missing ones:
        JUMP_AFTER_S, or JUMP_AFTER_PERIODS of the receiver's typical period where that is longer (a 1 Hz
        receiver's next fix comes 1.0 s later, give or take its jitter)."""
        return max(JUMP_AFTER_S, JUMP_AFTER_PERIODS * s.period[self.index])

    @staticmethod
    def _reacquire_after(own: GpsOwn, first: tuple, jump_after: float) -> float:
        """How long a run of gated-out fixes must last to say the filter is lost: REACQUIRE_S, or
        REACQUIRE_JUMP_S when the fixes jumped (the run's first fix came within ``jump_after`` of one the
        gate let in, and most of its offset is new). A filter drifts off continuously (dead-reckoning
        through a gap or a tunnel, a wrong heading); a receiver jumps: multipath (a 4 s burst 18 m
        off would be taken in after 3 s and left again 1 s later), a reset. Its new fixes may be right, but
        they have to keep saying so for longer."""
        return REACQUIRE_JUMP_S if _jumped(own.accepted, first[:3], jump_after) else REACQUIRE_S

    def _reacquire(self, s: "FilterState", z, inp: GpsInput, rows: tuple[int, ...], stamp: float,
                   emit: bool) -> None:
        """Put the base where the fix says and look for the heading again (it may be as wrong as the
        position was), as at the first fix but in the frame already defined."""
        own: GpsOwn = s.own[self.index]
        last = own.rejected[-1]
        if emit:  # once: not again for each re-application after a late sample
            log.warning("gps_reacquired", sensor=self.name, stamp=stamp, rejected=len(own.rejected),
                        seconds=stamp - own.rejected[0][0], offset=math.hypot(last[1], last[2]))
        self._set_from_fix(s, z, inp.cov, tuple(r for r in rows if r < 2))
        if self._scaled:
            self._rescale_wheels(s, own.rejected, emit, stamp)
        if not self.yaw_given:
            s.ekf.reset_covariance([YAW_ROW], np.array([[HEADING_UNKNOWN_SIGMA**2]]))
            s.heading_ready = False
        new_frame(s)
        self._start_track(s, z, inp.lla, stamp)

    def _rescale_wheels(self, s: "FilterState", run: tuple, emit: bool, stamp: float) -> None:
        """The wheels' scale as the re-acquiring run of fixes measures it: the fixes are the dead-reckoned track
        stretched by k (``_fitted_residual``), so the scale the track was driven with was short by that factor.
        The state's scale is multiplied by k and its variance opened by the change ((k - 1) scale)^2, so that the
        fixes that follow refine it: a scale stepping 20 % put every later fix out of the gate again."""
        _, k = _fitted_residual([(r[4], r[5]) for r in run], [(r[6], r[7]) for r in run], True)
        if not (math.isfinite(k) and k > 0.0) or k == 1.0:
            return
        ekf = s.ekf
        block = ekf.layout.nominal[WHEEL_SCALE]
        scale = float(ekf.x[block.start])
        change = scale * (k - 1.0)
        e = ekf.layout.error[WHEEL_SCALE].start
        var = float(ekf.P[e, e])
        ekf.shift(WHEEL_SCALE, [change])
        ekf.reset_variance(e, var + change * change)
        if emit:
            log.warning("gps_rescaled_wheels", sensor=self.name, stamp=stamp, wheel_scale=scale + change, factor=k)

    def _start_track(self, s: "FilterState", z, lla: tuple[float, float, float], stamp: float) -> None:
        """A new track (and heading search) from this fix; the receiver's measured noise goes on (its
        increments are the receiver's, whatever the filter lost)."""
        self._said_ready = False  # a new track: a new search, whose end is said again
        base = s.ekf.position()
        s.own[self.index] = GpsOwn(GpsTrack((), base, (z[0], z[1]), t0=stamp, last_lla=lla, last_dr=base[0:2],
                                                  last_enu=(z[0], z[1])), last=(stamp, z[0], z[1], base[0], base[1]),
                                   anchor=(base[0], base[1]), increments=s.own[self.index].increments)

    def _frozen(self, s: "FilterState", lla: tuple[float, float, float], z) -> bool:
        """Is this fix a repeat of the previous one although the robot has moved since those coordinates
        first came: bit for bit after FROZEN_MIN_TRAVEL, or within FROZEN_JITTER after FROZEN_JITTER_TRAVEL
        (a receiver that lost its fix and republishes it with rounding noise)? Independent fixes
        of a moving antenna are never bit-identical, nor a centimetre apart after half a metre; a robot
        at rest (odometry exactly zero: no dead-reckoned travel) may get repeats and fuses them.
        Remembers the fix otherwise (a repeat keeps the fix it repeats)."""
        own: GpsOwn = s.own[self.index]
        track, t = own.track, own.travel
        dr = (track.base[0] + t[0], track.base[1] + t[1])
        moved = math.hypot(dr[0] - track.last_dr[0], dr[1] - track.last_dr[1])
        if lla == track.last_lla:
            return moved > FROZEN_MIN_TRAVEL
        last = track.last_enu
        if last is not None and math.hypot(z[0] - last[0], z[1] - last[1]) <= FROZEN_JITTER:
            return moved > FROZEN_JITTER_TRAVEL
        s.own[self.index] = msgspec.structs.replace(
            own, track=msgspec.structs.replace(track, last_lla=lla, last_dr=dr, last_enu=(z[0], z[1])))
        return False

    def _heading(self, s: "FilterState", z: tuple[float, float, float], cov, stamp: float, emit: bool) -> None:
        """Add this fix to the track and fit; apply the fit once it is good enough (module doc)."""
        cfg = self.cfg
        own: GpsOwn = s.own[self.index]
        track, t = own.track, own.travel
        a = lever(s.ekf.x, cfg.extrinsic_xyz)
        dx, dy = track.base[0] + t[0] + a[0], track.base[1] + t[1] + a[1]  # dead-reckoned antenna
        var = max(cov[0], cov[4]) + self.wander
        point = (z[0], z[1], dx, dy, 1.0 / var)
        still = s.still_since
        if still is not None and still == track.rest and track.points:
            # Standing since the track's newest point: this fix measures the same place, and a receiver's slow
            # error is common to both. The hundreds of fixes of a parked spell are not as many independent
            # ones; weighted as such they pinned the track's start to their mean, wherever the receiver had
            # wandered, and the fit claimed a heading to a degree or two that was ten off. The newest stands
            # for the standstill: the fix nearest the drive, in time and in the receiver's error.
            points = track.points[:-1] + (point,)
            if len(points) == 1:  # the track has only stood: it starts here
                track = msgspec.structs.replace(track, first=(z[0], z[1]), extent=0.0, t0=stamp)
        else:
            points = track.points + (point,)
        if len(points) > HEADING_MAX_FIXES:
            points = points[::2] + ((points[-1],) if len(points) % 2 == 0 else ())
        extent = max(track.extent, math.hypot(z[0] - track.first[0], z[1] - track.first[1]))
        d0 = points[0]
        made = math.hypot(dx - d0[2], dy - d0[3]) >= HEADING_MIN_TRAVEL * math.hypot(z[0] - d0[0], z[1] - d0[1])
        fit = self._fit(points, extent, stamp - track.t0) if made else None
        # the shown position's heading until a fit is applied (``shown_position``): what the track says already
        guess = (fit.theta, fit.var_theta) if fit is not None and not track.applied else None
        track = msgspec.structs.replace(track, points=points, extent=extent, rest=still, guess=guess)
        s.own[self.index] = msgspec.structs.replace(own, track=track)
        if extent < max(cfg.heading_init_m, 4.0 * math.sqrt(var)):
            return
        if not made:
            # GPS wander or a pushed robot: the wheels did not make this track. Start over here.
            s.own[self.index] = msgspec.structs.replace(own, track=msgspec.structs.replace(
                track, points=((z[0], z[1], dx, dy, 1.0 / var),), first=(z[0], z[1]), extent=0.0, t0=stamp,
                guess=None))
            return
        if fit is None or fit.var_theta > HEADING_PROVISIONAL_SIGMA**2:
            return
        self._apply_fit(s, fit, track, t, emit)

    def _fit(self, points, extent: float, duration: float) -> RigidFit | None:
        """The rigid fit of the track's points (``fit_rigid``), its heading variance widened by what a modelled
        receiver wander can bend a track of this extent and duration by."""
        fit = fit_rigid(list(points))
        if fit is None or self.wander <= 0.0:
            return fit
        if extent <= 0.0:  # the fixes have not moved: nothing bounds what the wander bends
            return None
        # A slowly wandering error moves neighbouring fixes together: it bends the track as a
        # whole, which the residuals cannot show. Over the track's duration T its ends differ by
        # var(b(T) - b(0)) = 2 sigma_b^2 (1 - exp(-T / tau)), spread over the track's extent.
        drift = 2.0 * self.wander * -math.expm1(-duration / self.cfg.error_tau_s)
        return replace(fit, var_theta=fit.var_theta + drift / (extent * extent))

    def _apply_fit(self, s: "FilterState", fit: RigidFit, track: GpsTrack, t: tuple[float, float, float],
                   emit: bool) -> None:
        """Turn the state by the fit's angle about the antenna, which this fix has just put where the
        GPS says: the position dead-reckoned along the wrong heading since the previous fix turns with
        the heading, and P turns with both (``ErrorStateEKF.rotate_yaw``). The heading's row of P is
        then re-set to the fit's variance: its old correlations described the wrong heading."""
        ekf = s.ekf
        lever_mean, spread = self._unaligned_lever(ekf.yaw_variance())
        a = lever(ekf.x, lever_mean)
        p = ekf.position()
        antenna = (p[0] + a[0], p[1] + a[1])
        ekf.rotate_yaw(fit.theta, antenna)
        if spread > 0.0 and track.points:
            # The fixes pinned the antenna only to within the lever's circle while the heading was unknown: the
            # fit places it (the newest point's dead-reckoned antenna, turned and shifted onto the fixes), and
            # the base goes the whole lever back from there along the heading found.
            gx, gy = fit.apply(*track.points[-1][2:4])
            full = lever(ekf.x, self.cfg.extrinsic_xyz)
            ekf.set_position([gx - full[0], gy - full[1]], (0, 1))
        if self.ctx.layout.has("yaw_offset"):  # an absolute IMU yaw reads the same: its offset turns the other way
            ekf.shift("yaw_offset", [-fit.theta])
        # While the heading was unknown, the position's correlations with the gyro bias and the scales
        # were built through a heading error of ~1.8 rad: kept, they would feed the next fixes'
        # innovations into those states. They are dropped with the heading's row and column; the
        # position's own covariance and its relation to the GPS error state are what the fixes made them.
        group = list(POSITION_ROWS)
        if self._error_rows is not None:
            group += self._error_rows
        ekf.decorrelate(group)
        ekf.reset_covariance([YAW_ROW], np.array([[fit.var_theta]]))
        # the stored track is now seen in the turned frame: the next fit measures what is left
        points = tuple((gx, gy, *fit.apply(px, py), w) for gx, gy, px, py, w in track.points)
        bx, by = fit.apply(track.base[0] + t[0], track.base[1] + t[1])
        new_frame(s)  # the frame turned under the differential pose sensors: their deltas restart
        sigma = math.sqrt(fit.var_theta)
        ready = sigma <= HEADING_READY_SIGMA
        s.heading_ready = ready
        own: GpsOwn = s.own[self.index]
        # The receiver's measured noise outlives the turn: its increments are distances, which a turn keeps,
        # and the previous fix's dead-reckoned point turns with the track. Dropped at each refinement, the
        # fixes of the whole search went in at the unknown default (2.5 m) where they measured 0.1 m.
        last = own.last if own.last is None else (*own.last[0:3], *fit.apply(own.last[3], own.last[4]))
        s.own[self.index] = GpsOwn(msgspec.structs.replace(track, points=() if ready else points, base=(bx, by, track.base[2] + t[2]),
                                           applied=True, last_dr=fit.apply(*track.last_dr), guess=None),
                                   accepted=own.accepted,  # the jump check's reference stays
                                   increments=own.increments, last=last)
        # Said once a search, not again at each re-application after a late sample (the search may also
        # end first in a re-application: fixes stamped ahead of the odometry are re-applied at its every
        # message), so the flag lives on the model, outside the state the history rewinds.
        if ready and not self._said_ready:
            self._said_ready = True
            log.info("gps_heading_initialised", sensor=self.name, yaw_correction=fit.theta, sigma=sigma,
                     fixes=len(points))
        elif not ready and emit and not track.applied:
            log.info("gps_heading_provisional", sensor=self.name, yaw_correction=fit.theta, sigma=sigma,
                     fixes=len(points))

    def _unaligned_lever(self, s2: float) -> tuple[tuple[float, float, float], float]:
        """The antenna's lever arm as a fix sees it while the heading is searched for, its error psi ~ N(0, s2)
        about the state's placeholder: (the lever's mean, the variance of the antenna's place about it per
        horizontal axis). The antenna is at p + R(psi) t, and a turn about z moves only t's horizontal part:
        its mean is E[R(psi)] t_xy = exp(-s2/2) t_xy (as ``shown_position``'s displacement), its spread
        (|t_xy|^2 / 2)(1 - exp(-s2)) per axis, a circle of radius |t_xy| once nothing is known of psi. A
        linearised lever (dh/dpsi = -[R t]x, times s2 ~ (pi / sqrt 3)^2) would claim ~1.8 |t| on each axis where
        the antenna is |t| away at most: weighed against that, an RTK fix's centimetres leave the base metres
        behind the antenna, the fit turns the state about an antenna no fix placed, and the first fixes after it
        are gated and then taken for the wheels' scale (20 m off for 20 s on the highway car's RTK variant with
        the antenna half a metre back). Level roll and pitch are assumed, as by the heading search itself."""
        t = self.cfg.extrinsic_xyz
        h2 = t[0] * t[0] + t[1] * t[1]
        if h2 == 0.0:
            return t, 0.0
        k = math.exp(-0.5 * s2)
        return (k * t[0], k * t[1], t[2]), -0.5 * h2 * math.expm1(-s2)

    def _set_from_fix(self, s: "FilterState", z, cov, rows: tuple[int, ...]) -> None:
        """``set_position`` from a fix (the first, or a re-acquiring one) as the heading is then: given (an absolute
        IMU yaw trusted as heading), the base the lever back from the antenna; unknown (``HEADING_UNKNOWN_SIGMA``),
        the mean lever back (``_unaligned_lever``), the antenna's spread about it added to the fix's horizontal
        variance."""
        if self.yaw_given:
            set_position(s, z, cov, self.cfg.extrinsic_xyz, rows)
            return
        lever_mean, spread = self._unaligned_lever(HEADING_UNKNOWN_SIGMA**2)
        if spread > 0.0:
            cov = tuple(c + spread if i in (0, 4) else c for i, c in enumerate(cov))
        set_position(s, z, cov, lever_mean, rows)

    def _split_first_fix(self, s: "FilterState", rows: tuple[int, ...]) -> None:
        """The first fix put the base at z - R t, but z also carries the GPS error b: the base
        position is off by -(b + noise), so P_pp gains P_bb and P_pb = -P_bb (b keeps its prior).
        That is the change of variables dp <- dp - db: J = I with -I in the position rows' b columns."""
        layout = self.ctx.layout
        J = np.eye(layout.error_dim)
        eb = layout.error[self.error].start
        for i in rows:
            J[i, eb + i] = -1.0
        s.ekf.map_errors(J)


def _fitted_residual(fixes: list[tuple[float, float]], track: list[tuple[float, float]],
                     scaled: bool) -> tuple[float, float]:
    """(RMS distance (m) of the fixes from the dead-reckoned track at their stamps once the track is turned,
    stretched by k and shifted onto them (the least-squares similarity in the plane), k): what no error of the
    filter's heading, position and wheel scale explains. ``scaled`` False, or a track that did not move: k = 1,
    the rigid fit (rotation and offset), for a filter without the wheels' scale in its state."""
    n = len(fixes)
    fx, fy = sum(p[0] for p in fixes) / n, sum(p[1] for p in fixes) / n
    tx, ty = sum(p[0] for p in track) / n, sum(p[1] for p in track) / n
    dot = cross = norm = 0.0
    for (a, b), (c, d) in zip(fixes, track):
        a, b, c, d = a - fx, b - fy, c - tx, d - ty
        dot += a * c + b * d
        cross += b * c - a * d
        norm += c * c + d * d
    k = math.hypot(dot, cross) / norm if scaled and norm > 0.0 else 1.0
    turn = math.atan2(cross, dot)
    kc, ks = k * math.cos(turn), k * math.sin(turn)
    sq = 0.0
    for (a, b), (c, d) in zip(fixes, track):
        c, d = c - tx, d - ty
        sq += (a - fx - (kc * c - ks * d)) ** 2 + (b - fy - (ks * c + kc * d)) ** 2
    return math.sqrt(sq / n), k


def _jumped(last: tuple | None, first: tuple, jump_after: float) -> bool:
    """Did a run of gated-out fixes begin with a jump of the fixes: its first, ``first`` (t, innovation
    components...), within ``jump_after`` of ``last``, the newest one the gate let in (the same components;
    ``GpsModel._jump_after``), and most of its offset new (``_reacquire_after``, ``_altitude_lost``)?"""
    if last is None or first[0] - last[0] > jump_after:
        return False
    return math.hypot(*(f - a for f, a in zip(first[1:], last[1:]))) > 0.5 * math.hypot(*first[1:])


def _step_start(y: np.ndarray, R: np.ndarray, hp: np.ndarray) -> StepRun:
    """The step test's sums over one fix: innovation ``y``, fix covariance ``R``, filter's H P H^T ``hp``."""
    Ri = np.linalg.inv(R)
    iy = Ri.dot(y)
    i0, i1, i2, i3 = Ri.ravel().tolist()
    h0, h1, h2, h3 = hp.ravel().tolist()
    return StepRun(1, (i0, i1, i2, i3), (float(iy[0]), float(iy[1])), float(y.dot(y)), (h0, h1, h2, h3))


def _log_normal2(r: np.ndarray, cov: np.ndarray) -> float:
    """log N(r; 0, cov) of a 2-vector."""
    a, b, c = float(cov[0, 0]), 0.5 * float(cov[0, 1] + cov[1, 0]), float(cov[1, 1])
    det = a * c - b * b
    if det <= 0.0:
        return -math.inf
    q = (c * r[0] * r[0] - 2.0 * b * r[0] * r[1] + a * r[1] * r[1]) / det
    return -0.5 * q - 0.5 * math.log(det) - math.log(2.0 * math.pi)


def _step_llr(st: StepRun, y: np.ndarray, R: np.ndarray, hp: np.ndarray) -> float:
    """lambda_k of the module doc ("Steps"): what fix k (innovation ``y``, fix covariance ``R``, filter's
    H P H^T ``hp``) says for "one offset since the run began" against "an outlier", given the run's sums."""
    C = np.linalg.inv(np.array(st.info).reshape(2, 2))
    d = C.dot(np.array(st.info_y))
    grown = hp - np.array(st.hp0).reshape(2, 2)  # the dead-reckoning's growth of the filter's error since
    w, v = np.linalg.eigh(0.5 * (grown + grown.T))  # the run began (its positive part: P may also shrink
    G = (v * np.maximum(w, 0.0)).dot(v.T)  # through a correlated update of another sensor)
    l1 = _log_normal2(y - d, R + C + G)
    m2 = st.sq / (2.0 * st.n)
    S = hp + R
    # an outlier of the run's size, or an ordinary fix at the filter's position that the gate caught (a
    # gate set within the noise rejects those in runs, scattered about the old position, not a new one)
    a, b = _log_normal2(y, S + m2 * np.eye(2)), _log_normal2(y, S)
    l0 = max(a, b) + math.log1p(math.exp(-abs(a - b))) - math.log(2.0)
    if l1 == -math.inf:
        return -math.inf
    e = l0 - l1
    if e > 700.0:  # exp would overflow: the (1 - rho) p0 term alone
        return -e - math.log1p(-BURST_REPEAT)
    return -math.log((1.0 - BURST_REPEAT) * math.exp(e) + BURST_REPEAT)


def _back_llr(st: StepRun, y: np.ndarray, R: np.ndarray, hp: np.ndarray, left: tuple[float, float, float]) -> float:
    """What a gated-out fix says for "back at the level the last step left" (module doc, "Steps"): the
    innovation seen from that level, y + d_left ~ N(0, H P H^T + R), against an outlier of the run's size
    (``st`` includes this fix). A known level has no offset to estimate and a burst that ends returns to
    it: no cap, one or two fixes decide."""
    S = hp + R
    l1 = _log_normal2(y + np.array(left[1:]), S)
    l0 = _log_normal2(y, S + (st.sq / (2.0 * st.n)) * np.eye(2))
    return l1 - l0


def _upper_variance(sq: float, n: int) -> float | None:
    """The upper confidence bound (NOISE_UPPER_Z) of sigma^2 from n increments d, E d^2 = 2 sigma^2, whose
    squares sum to ``sq``: sq / (2 sigma^2) is chi-square with n dof, so sigma^2 <= sq / (2 q) with q its
    lower quantile, by Wilson and Hilferty's cube-root normal approximation (a few per cent at n >= 5,
    on the large, safe side below). None while n is too small for any bound (q not positive: n <= 2)."""
    if n <= 0:
        return None
    h = 2.0 / (9.0 * n)
    root = 1.0 - h - NOISE_UPPER_Z * math.sqrt(h)
    if root <= 0.0:
        return None
    return sq / (2.0 * n * root**3)


def measured_axes(cfg: GpsSensor, cov) -> tuple[int, ...]:
    """The ENU axes the fix measures: a variance above ``max_sigma``^2 means "not measured"."""
    limit = cfg.max_sigma * cfg.max_sigma
    return tuple(i for i in range(3) if cov[4 * i] <= limit)


__all__ = ["GpsInput", "GpsModel", "GpsOwn", "GpsPolicy", "GpsTrack", "StepRun"]
