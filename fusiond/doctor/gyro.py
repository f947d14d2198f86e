"""The gyro at standstill against the filter's bias estimate.

While the robot stands (the wheels reading exactly zero, or the filter's rest test passing on a drive
that reads noise at rest), the gyro should read its bias. Each standstill
episode gives the gyro's mean there; genuine standstills agree with each other to
the gyro noise over the episode (sigma / sqrt(n)). An episode that reads clearly
differently from the others is a false standstill (the vehicle coasting or turning
with its wheels at zero). If the filter ACCEPTED that one and rejected the genuine
ones after it, the accepted one is the cause: it set the bias, and the genuine ones
then look like outliers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Config, ImuSensor
from ..core.sensors.registry import kind_of
from ..core.sensors.imu.gyro_bias import _turning, quiet_bound
from ..core.sensors.odom.model import impossible_stop
from .bins import BIN_S
from .lost import none_fused
from .median import median
from .nis import ChannelStats, judge_nis
from .series import Series
from .verdict import Verdict, filter_key, sensor_key


MIN_REJECTED_FRACTION = 0.1  # rejected standstill updates beyond a tenth: more than a gate's chance ones
OVERSTATED_RATIO = 3.0  # a stated gyro noise this many times the measured one at rest is overstated
# the gyro's noise at rest measured beyond this factor of the stated (either way) explains a NIS high or low;
# within it, the noise is as stated
NOISE_RATIO = 1.5
DISAGREE_RAD_S = 0.003  # episodes whose gyro means differ by more than this (and 5 sigma) disagree
MIN_DRIFT_EPISODES = 3  # a drift is told from one odd standstill by its trend, which takes three points
DRIFT_WALK_MARGIN = 2.0  # a drift is named when the walk it shows exceeds the configured one by this factor


@dataclass
class Episode:
    t0: float
    t1: float
    gyro_mean: float = math.nan
    gyro_sigma: float = math.nan  # within-episode std of the gyro samples
    samples: int = 0
    accepted: int = 0
    rejected: int = 0

    @property
    def spread(self) -> float:
        """Standard error of the episode's mean."""
        return self.gyro_sigma / math.sqrt(self.samples) if self.samples > 1 else math.inf


def has_heading_reference(cfg: Config, stats: dict[str, dict] | None) -> bool:
    """Does a sensor that observes heading (a GPS, a pose, an IMU's absolute or relative yaw) take part: one
    configured and, when the per-sensor counts are known, one that delivered a sample (a configured sensor
    that stayed silent, replayed with --allow-missing, references nothing)."""
    def delivered(name: str) -> bool:
        return stats is None or stats.get(name, {}).get("received", 0) > 0

    return any(kind_of(s).heading_reference(s) and delivered(s.name) for s in cfg.sensors)


def gyro_imu(cfg: Config) -> ImuSensor | None:
    """The configured IMU whose gyro is fused (the one whose bias the standstills learn), if any."""
    return next((s for s in cfg.sensors if kind_of(s).inertial and kind_of(s).fuses_gyro(s)), None)


def rest_bias(episodes: list[Episode]) -> float:
    """The gyro's z bias as it reads at rest: the median of the standstills' means (NaN without one). One
    figure for every check that names it: the first standstill alone can be a short, noisy one (a few
    samples whose mean is off by twice its scatter) or a false one, and the bias moves over a run."""
    means = [e.gyro_mean for e in episodes if math.isfinite(e.gyro_mean)]
    return float(median(means)) if means else math.nan


def standstill_episodes(series: Series, standstill_s: float, coast_decel: float = 0.0) -> list[Episode]:
    """The standstills lasting at least standstill_s, with the gyro over them: the runs of bins reading
    exactly zero, and the filter's own where a replay reported them (``Series.rest_spans``: its odometry
    rest test, which also finds a drive reading noise at rest). A zero run the filter did not take for rest
    stays unless it began as a coast (``_zero_runs``); ``quiet_episodes`` tells a turning one by its gyro."""
    out = _zero_runs(series, standstill_s, coast_decel)
    if series.rest_spans:
        # bounds on the bins' middles: a gyro bin is taken whole inside the standstill, never half in the drive
        half = BIN_S / 2
        spans = [Episode(t0 + half, t1 - half) for t0, t1 in series.rest_spans if t1 - t0 >= standstill_s + BIN_S]
        out = sorted(spans + [e for e in out if not any(e.t0 <= s.t1 and s.t0 <= e.t1 for s in spans)],
                     key=lambda e: e.t0)
    if not out or not series.gyro_t:
        return out
    bins = _gyro_bins(series)
    for e in out:
        _gyro_stats(e, bins, standstill_s)
    return out


def _gyro_bins(series: Series) -> tuple[np.ndarray, ...]:
    """(stamps, mean z, variance within, samples) of the gyro's bins."""
    return (np.array(series.gyro_t), np.array(series.gyro_z), np.array(series.gyro_var), np.array(series.gyro_n))


def _gyro_stats(e: Episode, bins: tuple[np.ndarray, ...], standstill_s: float) -> None:
    """The gyro over episode ``e`` from standstill_s after it began: its samples, mean and scatter."""
    tg, z, var, n = bins
    m = (tg >= e.t0 + standstill_s) & (tg <= e.t1)
    if m.sum() == 0:
        return
    w = n[m]
    e.samples = int(w.sum())
    e.gyro_mean = float(np.sum(z[m] * w) / w.sum())
    within = np.sum(var[m] * np.maximum(w - 1, 0))
    between = np.sum(w * (z[m] - e.gyro_mean) ** 2)
    e.gyro_sigma = float(math.sqrt((within + between) / max(e.samples - 1, 1)))


def _quiet_runs(e: Episode, bins: tuple[np.ndarray, ...], bound: float, standstill_s: float) -> list[Episode] | None:
    """None when every gyro bin of ``e`` (from standstill_s in) reads within ``bound``; else the stretch after
    its last loud bin, as an episode of its own (none when it ends loud). An odometry rest span can begin while
    the vehicle still turns (a drive at 5 Hz reading zero twice in a slow turn, and the filter's rest test
    taking it), then settle: averaged whole, the turn's rates made a noise at rest of 0.057 rad/s on the F1/10,
    19 times the gyro's. A quiet stretch with a loud bin after it, the wheels still at zero, is no standstill:
    a parked vehicle does not start to turn with its wheels at rest, a pushed one does, between its quiet
    straight pieces (an F1/10 pushed 10 s at 1.4 m/s: ten such pieces read a noise at rest of 0.023 rad/s,
    7 times the gyro's, and the line stating it made the filter learn its bias mid-push)."""
    tg, z = bins[0], bins[1]
    m = (tg >= e.t0 + standstill_s) & (tg <= e.t1)
    loud = m & (np.abs(z) > bound)
    if not loud.any():
        return None
    inside = np.nonzero(m)[0]
    last_loud = inside[loud[inside]][-1]
    if last_loud == inside[-1]:
        return []  # loud to its end: no stretch of it settled
    # from the bin after the last loud one, less standstill_s, as a standstill's statistics are taken
    sub = Episode(float(tg[last_loud + 1]) - standstill_s, float(tg[inside[-1]]))
    _gyro_stats(sub, bins, standstill_s)
    return [sub]


def _runs(series: Series, coast_decel: float) -> list[tuple[float, float, float]]:
    """(first bin, last bin, end of the coast) of each run of odometry bins exactly at rest. A run the drive
    dropped into from a speed no vehicle stops from within a bin (``impossible_stop``, the core's own test) is a
    coast while that speed would last at ``coast_decel``, as the core rolls the position on over it
    (core/sensors/odom/model.py): a highway car whose drive reads zero for 3 s at 19 m/s is still doing 18 m/s,
    its gyro as quiet as at rest on a straight road. The coast's end is the run's first bin otherwise."""
    t, v, rest = series.odom_t, series.odom_v, series.odom_rest
    out: list[tuple[float, float, float]] = []
    start = coast_end = None
    for i, r in enumerate(rest):
        if r and start is None:
            start = coast_end = t[i]
            if coast_decel > 0.0 and i > 0 and not rest[i - 1] and math.isfinite(v[i - 1]):
                speed = abs(v[i - 1])
                if impossible_stop(speed, t[i] - t[i - 1], BIN_S):
                    coast_end = start + speed / coast_decel
        if (not r or i == len(t) - 1) and start is not None:
            out.append((start, t[i] if r else t[i - 1], coast_end))
            start = None
    return out


def _zero_runs(series: Series, standstill_s: float, coast_decel: float = 0.0) -> list[Episode]:
    """Runs of odometry bins exactly at rest lasting at least standstill_s once their coast (``_runs``) is over."""
    return [Episode(coast_end, end) for _, end, coast_end in _runs(series, coast_decel) if end - coast_end >= standstill_s]


def coasts(series: Series, cfg: Config) -> list[tuple[float, float]]:
    """(first, last bin) of the drive's zero runs that began as a coast (``_runs``), up to the coast's end or the
    run's: the wheels' travel stopped there while the vehicle did not (the speed check leaves them out)."""
    return [(start, min(end, coast_end)) for start, end, coast_end in _runs(series, _coast_decel(cfg))
            if coast_end > start]


def rest_windows(series: Series, cfg: Config) -> list[tuple[float, float]]:
    """Where the robot stood, as the doctor reads a noise at rest: each standstill (``standstill_episodes``) from
    standstill_s after the filter took it, when its rest is confirmed (before that a vehicle still settling on
    its suspension, or still rolling as its drive reads zero, shows as noise), to its end; with a gyro fused,
    not one whose gyro turns (``quiet_episodes``). Tune's floors (``tune/floors.py``) measure over these, so the
    doctor and tune read one noise at rest from the same stretches of the recording."""
    standstill_s = cfg.filter.standstill_s
    imu = gyro_imu(cfg)
    if imu is not None and series.gyro_t:
        episodes, _ = quiet_episodes(series, cfg, imu)
    else:
        episodes = standstill_episodes(series, standstill_s, _coast_decel(cfg))
    half = BIN_S / 2  # the episodes' bounds are on bin middles: a bin reaches half a bin either side
    return [(e.t0 - half + standstill_s, e.t1 + half) for e in episodes if e.t1 + half > e.t0 - half + standstill_s]


def turning_by_own_scatter(e: Episode, bias_sigma: float, min_sigma: float) -> bool:
    """Does the episode's mean rate exceed the quiet bound of its readings' OWN scatter? The core's test
    of a closed standstill window (``core/sensors/imu/gyro_bias._turning``, called here on the episode's z
    axis as a window): a driver overstating its gyro noise (razor_imu_9dof states 0.14 rad/s for a
    0.004 rad/s gyro) makes a slow turn with the drive at zero pass for rest by the stated noise."""
    n = e.samples
    if n < 2 or not (math.isfinite(e.gyro_mean) and math.isfinite(e.gyro_sigma)):
        return False
    sq = (e.gyro_sigma**2 * (n - 1) / n + e.gyro_mean**2) * n  # sum of squares with this mean and scatter
    window = (e.t0, n, 0.0, 0.0, e.gyro_mean * n, 0.0, 0.0, 0.0, 0.0, 0.0, sq)
    return _turning(window, bias_sigma, min_sigma)


def _coast_decel(cfg: Config) -> float:
    """The odometry's coast-down (m/s^2; 0: no coast held, and none without an odometry sensor)."""
    odom = next((s for s in cfg.sensors if kind_of(s).drives_prediction), None)
    return float(getattr(odom, "coast_decel", 0.0)) if odom is not None else 0.0


def _count_updates(episodes: list[Episode], ch: ChannelStats | None) -> None:
    if ch is None:
        return
    bounds = np.array([e.t1 for e in episodes])
    for stamp, rej in zip(ch.stamps, ch.rejected_flags):
        i = int(np.searchsorted(bounds, stamp - 0.5))
        if i < len(episodes) and episodes[i].t0 - 0.5 <= stamp <= episodes[i].t1 + 0.5:
            if rej:
                episodes[i].rejected += 1
            else:
                episodes[i].accepted += 1


def _coast_note(cfg: Config) -> str:
    """What the position does while the drive reads zero and the vehicle moves (core/sensors/odom/model.py)."""
    odom = next(s for s in cfg.sensors if kind_of(s).drives_prediction)
    if odom.coast_decel <= 0.0:
        return (f"The position does not advance while the wheels read zero ({sensor_key(odom.name, 'coast_decel')} "
                "= 0: a coast is not held)")
    return (f"Where the drive dropped to zero faster than a vehicle can stop, the position ran on from the last "
            f"speed, slowing at {odom.coast_decel:g} m/s^2 until it stopped ({sensor_key(odom.name, 'coast_decel')}); "
            "otherwise, and after that, it does not advance while the wheels read zero")


def bias_drift(episodes: list[Episode], walk: float) -> tuple[tuple[float, float], tuple[float, float], float] | None:
    """A gyro bias that drifts steadily across the standstills: ((t, b) first, (t, b) last, the random walk
    that drift shows, |change| / sqrt(span)), or None.

    One odd standstill (the vehicle coasting while its wheels read zero) sits off a line through the others;
    a bias drifting with temperature puts every standstill on one smooth line. So: a line b = a + r t fitted
    through MIN_DRIFT_EPISODES or more standstills' gyro means leaves each within max(5 x its standard error,
    DISAGREE_RAD_S / 3), and its change over the span exceeds DISAGREE_RAD_S and what the configured walk
    allows (DRIFT_WALK_MARGIN x walk x sqrt(span))."""
    if len(episodes) < MIN_DRIFT_EPISODES:
        return None
    t = np.array([e.t0 for e in episodes])
    b = np.array([e.gyro_mean for e in episodes])
    if not np.all(np.isfinite(b)) or np.ptp(t) <= 0.0:
        return None
    slope, intercept = np.polyfit(t, b, 1)
    resid = b - (intercept + slope * t)
    tol = np.array([max(5.0 * e.spread, DISAGREE_RAD_S / 3.0) for e in episodes])
    span = float(t[-1] - t[0])
    change = float(slope * span)
    if np.any(np.abs(resid) > tol) or abs(change) <= DISAGREE_RAD_S:
        return None
    shown = abs(change) / math.sqrt(span)
    if shown <= DRIFT_WALK_MARGIN * walk:
        return None
    return (float(t[0]), float(b[0])), (float(t[-1]), float(b[-1])), shown


def _high_axes(ch: ChannelStats) -> dict[str, float]:
    """The standstill windows' axes whose own mean NIS (one dof each, over the channel's updates) is beyond
    the channel's upper bound, with that NIS: which bias the standstills disagree with."""
    out = {}
    for i, axis in enumerate(ch.components):
        _, rms, predicted = ch.component(i)
        if predicted > 0.0 and math.isfinite(rms):
            nis = (rms / predicted) ** 2
            if judge_nis(nis, ch.n_comp, 1.0, ch.confidence) == "nis_high":
                out[axis] = nis
    return out


def quiet_episodes(series: Series, cfg: Config, imu: ImuSensor) -> tuple[list[Episode], list[Episode]]:
    """(standstills, stretches that only look like one): the standstill episodes, split by the gyro.

    The core confirms a standstill only while the gyro is quiet (each axis within quiet_bound: its noise
    plus the prior bias range, core/sensors/imu/gyro_bias.py): an episode whose gyro turns is the vehicle
    coasting or turning with its wheels reading zero, not a standstill; one that turns in part of it keeps
    its quiet stretches (``_quiet_runs``). So is one beyond the quiet bound
    of the readings' own scatter (the stated noise may be overstated tenfold), as the core judges a closed
    window; their scatter (the turn rate changing) must not enter the measured noise at rest."""
    fc = cfg.filter
    stated = series.gyro_stated_sigma if math.isfinite(series.gyro_stated_sigma) else 0.0
    bound = quiet_bound(stated, fc.gyro_bias_sigma)
    episodes, turning = [], []
    bins = _gyro_bins(series) if series.gyro_t else None
    for e in standstill_episodes(series, fc.standstill_s, _coast_decel(cfg)):
        runs = _quiet_runs(e, bins, bound, fc.standstill_s) if bins is not None and e.samples > 1 else None
        if runs is None:
            episodes.append(e)
        else:  # the vehicle turned in part of it: that part is no standstill, its quiet stretches may be
            turning.append(e)
            episodes.extend(runs)
    episodes = [e for e in episodes if e.samples > 1]
    turns = [abs(e.gyro_mean) > bound or turning_by_own_scatter(e, fc.gyro_bias_sigma, imu.gyro_min_sigma)
             for e in episodes]
    rest = [e for e, f in zip(episodes, turns) if not f]
    return rest, sorted(turning + [e for e, f in zip(episodes, turns) if f], key=lambda e: e.t0)


def bias_check(series: Series, cfg: Config, ch: ChannelStats | None, gyro_fused: bool,
               stats: dict[str, dict] | None = None) -> Verdict | None:
    imu = gyro_imu(cfg)
    if imu is None or not gyro_fused:
        return None
    if none_fused(stats, imu.name):
        return None  # none of its samples reached the filter: the input verdict says why
    fc = cfg.filter
    episodes, turning = quiet_episodes(series, cfg, imu)
    if turning and (ch is None or ch.n == 0 or not episodes):
        t_start = series.odom_t[0]
        worst = max(turning, key=lambda e: abs(e.gyro_mean))
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"the wheels read exactly zero in {len(turning)} stretch(es) while the gyro turned (the "
                       f"most by {worst.gyro_mean * (worst.t1 - worst.t0):+.2f} rad in {worst.t1 - worst.t0:.1f} s "
                       f"from {worst.t0 - t_start:.1f} s in): the vehicle coasted or turned "
                       "with its drive reporting zero. Those are rightly not taken as standstills (the gyro bias is "
                       f"not learned there). {_coast_note(cfg)}",
                       evidence={"turning_at_rest": float(len(turning)), "turning_rate_rad_s": worst.gyro_mean})
    if not series.gyro_t and (ch is None or ch.n == 0) and len(series.odom_t) > 1:
        # the odometry ran and this IMU sent nothing: "never learned" would blame the driving, not the topic
        return Verdict(imu.name, "gyro_bias", "warn",
                       "no gyro sample from this IMU in the recording while the odometry ran (its topic absent, or "
                       "every sample lost): the gyro drove nothing and its bias was never learned; check its key",
                       sensor_key(imu.name, "key"), evidence={"gyro_samples": 0.0})
    heading_ref = has_heading_reference(cfg, stats)
    duration = (series.odom_t[-1] - series.odom_t[0]) if len(series.odom_t) > 1 else 0.0
    if not episodes and (ch is None or ch.n == 0):
        if heading_ref or duration <= 0.0:
            return None
        drift = fc.gyro_bias_sigma * duration
        return Verdict(imu.name, "gyro_bias", "warn",
                       "the gyro's z bias, which turns the heading, was never learned (a tilt reference learns "
                       f"x and y only): no standstill of {fc.standstill_s:g} s in {duration:.0f} s "
                       f"and no heading reference, so heading uncertainty grows by gyro_bias_sigma x t "
                       f"({fc.gyro_bias_sigma:g} rad/s -> {drift:.2f} rad over the run). Stop the robot now and then, "
                       "or state the bias spread `fusiond calibrate-imu` measures on a minute of the IMU at rest "
                       "(a recording of its own: this one never stands still)",
                       filter_key("gyro_bias_sigma"), evidence={"duration_s": duration, "standstills": 0.0})
    _count_updates(episodes, ch)
    evidence: dict[str, float] = {"standstills": float(len(episodes))}
    if turning:
        evidence["turning_at_rest"] = float(len(turning))
    drift = bias_drift(episodes, fc.gyro_bias_walk)
    if len(episodes) >= 2:
        ref = rest_bias(episodes)
        evidence["gyro_at_rest_rad_s"] = ref

        def odd(e: Episode) -> bool:
            return abs(e.gyro_mean - ref) > max(5.0 * e.spread, DISAGREE_RAD_S)

        suspects = [e for e in episodes if odd(e) and e.accepted > 0]
        later_rejected = [e for e in episodes if not odd(e) and e.rejected > e.accepted]
        if suspects and later_rejected and later_rejected[-1].t0 > suspects[0].t0 and drift is None:
            s = suspects[0]
            t_start = series.odom_t[0]
            evidence.update({"suspect_t_s": s.t0 - t_start, "suspect_gyro_rad_s": s.gyro_mean})
            return Verdict(imu.name, "gyro_bias", "problem",
                           f"the standstill at {s.t0 - t_start:.1f} s was ACCEPTED although the gyro read "
                           f"{s.gyro_mean:+.4f} rad/s there, while the other {len(episodes) - len(suspects)} "
                           f"standstills read {ref:+.4f} rad/s: the wheels read zero while the vehicle still turned "
                           f"or coasted, and that update set the bias; the {len(later_rejected)} genuine standstills "
                           "after it were then rejected against the wrong bias. Confirm standstills for longer"
                           + ("" if len(episodes) >= MIN_DRIFT_EPISODES else
                              " (or, with two standstills only, the bias drifted between them, e.g. with temperature: "
                              "then raise gyro_bias_walk instead)"),
                           filter_key("standstill_s"), f"standstill_s = {max(2.0 * fc.standstill_s, 1.0):g}",
                           evidence)
    if episodes and series.est_bias_z:
        evidence["bias_estimate_rad_s"] = float(np.interp(episodes[-1].t1, series.est_t, series.est_bias_z))
    if ch is None or ch.n == 0:
        return None
    frac = ch.rejected / ch.n
    sig = [e.gyro_sigma for e in episodes if math.isfinite(e.gyro_sigma)]
    measured = float(median(sig)) if sig else math.nan
    if math.isfinite(measured):
        evidence["gyro_sigma_at_rest_rad_s"] = measured
    noise_hint = f"gyro_noise = {measured:.5f}" if math.isfinite(measured) else ""
    stated = series.gyro_stated_sigma
    if math.isfinite(stated):
        evidence["gyro_sigma_stated_rad_s"] = stated
    if math.isfinite(measured) and math.isfinite(stated) and stated > OVERSTATED_RATIO * measured:
        # a gyro stated far noisier than it is weighs every standstill window (and, fused, every turn)
        # too little: the filter learns its bias slowly and the NIS of what it does learn reads low
        rejected = (f"; {100 * frac:.0f}% of the standstill bias updates were rejected" if frac > MIN_REJECTED_FRACTION
                    else "")
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"the gyro noise is overstated: it measures {measured:.5f} rad/s at rest (median of "
                       f"{len(sig)} standstills), {stated:.5f} is stated ({stated / measured:.0f}x){rejected}. "
                       "State the measured noise", sensor_key(imu.name, "gyro_noise"), noise_hint, evidence)
    if frac > MIN_REJECTED_FRACTION:
        moving = [e for e in episodes if e.rejected and math.isfinite(measured) and e.gyro_sigma > 3.0 * measured]
        if moving:
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"{100 * frac:.0f}% of standstill bias updates rejected: the robot turned while its wheels "
                           "read zero (pushed or carried); those updates are rightly refused",
                           filter_key("standstill_s"), evidence=evidence)
        if math.isfinite(measured) and math.isfinite(stated) and measured > NOISE_RATIO * stated:
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"{100 * frac:.0f}% of standstill bias updates rejected: the gyro noise is understated "
                           f"(it measures {measured:.5f} rad/s at rest, {stated:.5f} is stated)",
                           sensor_key(imu.name, "gyro_noise"), noise_hint, evidence)
        if drift is not None:  # a steady trend across the standstills, not one odd one
            (t_a, b_a), (t_b, b_b), walk = drift
            t_start = series.odom_t[0]
            evidence.update({"bias_drift_rad_s": b_b - b_a, "bias_drift_over_s": t_b - t_a})
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"the gyro's bias drifts: at rest it reads {b_a:+.4f} rad/s at {t_a - t_start:.0f} s and "
                           f"{b_b:+.4f} at {t_b - t_start:.0f} s, steadily across the {len(episodes)} standstills "
                           f"(temperature), faster than gyro_bias_walk ({fc.gyro_bias_walk:g} rad/s/sqrt(s)) lets the "
                           "filter follow: standstill updates are rejected against the old bias, and the heading turns "
                           "with the difference meanwhile. State the walk the drift shows",
                           filter_key("gyro_bias_walk"), f"gyro_bias_walk = {walk:.2g}", evidence)
        est = evidence.get("bias_estimate_rad_s", math.nan)
        ref = evidence.get("gyro_at_rest_rad_s", episodes[-1].gyro_mean if episodes else math.nan)
        if math.isfinite(est) and math.isfinite(ref) and abs(est - ref) <= max(DISAGREE_RAD_S / 3.0, 3.0 * (
                episodes[-1].spread if episodes else 0.0)):
            # z agrees: the rejected part is an x/y axis, whose bias roll/pitch updates also move
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"{100 * frac:.0f}% of standstill bias updates rejected, though the z bias ({est:+.5f} "
                           f"rad/s) agrees with the gyro at rest ({ref:+.5f}): the rejections are on the x/y axes, "
                           "whose bias the roll/pitch updates also move (a tilting or rocking robot at rest, or IMU "
                           "roll/pitch that wanders); heading is not affected",
                           evidence=evidence)
        if not (math.isfinite(measured) and math.isfinite(stated)):
            # no standstill of the gyro in the series (the live monitor has only the updates): the noise at rest,
            # which tells an understated noise from a bias estimate moved by another source, is not measured
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"{100 * frac:.0f}% of standstill bias updates rejected ({ch.n} updates): the standstills "
                           "disagree with the filter's bias estimate. Its gyro's noise at rest is not measured here "
                           "(no standstill in what the doctor saw of the gyro): `fusiond doctor` on a recording of "
                           "the robot tells an understated gyro_noise from a bias estimate moved by another source",
                           evidence=evidence)
        evidence["bias_moved"] = 1.0
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"{100 * frac:.0f}% of standstill bias updates rejected although the gyro is quiet at rest "
                       f"({measured:.5f} rad/s, {stated:.5f} stated) and reads {ref:+.5f} rad/s there: the filter's "
                       f"bias estimate ({est:+.5f}) was moved by another source, and the standstills now contradict it",
                       evidence=evidence)
    v = ch.verdict()
    if v == "nis_high" and math.isfinite(measured) and math.isfinite(stated) and measured <= NOISE_RATIO * stated:
        # the noise at rest is what is stated (within NOISE_RATIO, as "understated" above): what the standstills
        # disagree with is the bias estimate, moved between them by something else; pasting the measured
        # noise would change nothing (it would tell the user to paste the gyro_noise already configured)
        yaw = imu.fuses_yaw
        high = _high_axes(ch)
        if high and "gyro_z" not in high:
            # z, the heading's, agrees: the x/y biases disagree, which the roll/pitch updates move too
            evidence.update({f"nis_{a}": v for a, v in high.items()})
            shown = ", ".join(f"{a[-1]} {v:.1f}" for a, v in high.items())
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"standstill gyro NIS high ({ch.nis_per_dof:.1f} per dof over {ch.n} updates) on the "
                           f"x/y axes only (per axis: {shown}; z within its bounds), although the gyro's noise at "
                           f"rest is as stated ({measured:.5f} rad/s measured, {stated:.5f} stated): the x/y bias "
                           "estimates, which the roll/pitch updates also move (a tilting or rocking robot at rest, "
                           "or IMU roll/pitch that errs while driving: see imu/orientation), disagree with the "
                           "standstills; heading is not affected", evidence=evidence)
        est = evidence.get("bias_estimate_rad_s", math.nan)
        last = episodes[-1] if episodes else None
        at_rest = (f", {est:+.5f} estimated against {last.gyro_mean:+.5f} read at the last standstill "
                   f"({last.t0 - series.odom_t[0]:.0f} s in)") if last is not None and math.isfinite(est) else ""
        evidence["bias_moved"] = 1.0
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"standstill gyro NIS high ({ch.nis_per_dof:.1f} per dof over {ch.n} updates) although the "
                       f"gyro's noise at rest is as stated ({measured:.5f} rad/s measured, {stated:.5f} stated): "
                       f"between the standstills something else moves the filter's bias estimate{at_rest}"
                       + (f": the IMU's fused yaw (orientation = \"{imu.orientation}\") drags it when that yaw drifts "
                          "against the gyro (see imu/orientation)" if yaw else
                          ": a bias that drifts faster than gyro_bias_walk lets it follow, or the heading source"),
                       evidence=evidence)
    if v == "nis_high":
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"standstill gyro NIS high ({ch.nis_per_dof:.1f} per dof over {ch.n} updates): the gyro noise "
                       "is understated" + (f"; it measures {measured:.5f} rad/s at rest" if noise_hint else ""),
                       sensor_key(imu.name, "gyro_noise"), noise_hint, evidence)
    # Each standstill window makes one update per axis; the first ones are judged against the wide
    # bias prior, so a low NIS alone says the prior was wide, not that the noise is overstated:
    # only the measured spread at rest can say that.
    if v == "nis_low" and math.isfinite(measured) and math.isfinite(stated) and measured < stated / NOISE_RATIO:
        return Verdict(imu.name, "gyro_bias", "warn",
                       f"standstill gyro NIS low ({ch.nis_per_dof:.2f} per dof over {ch.n} updates): the gyro noise "
                       "is overstated" + (f"; it measures {measured:.5f} rad/s at rest" if noise_hint else ""),
                       sensor_key(imu.name, "gyro_noise"), noise_hint, evidence)
    against = ""
    if episodes and "bias_estimate_rad_s" in evidence:
        last = episodes[-1]
        against = (f"; bias estimate {evidence['bias_estimate_rad_s']:+.5f} rad/s, the gyro at rest reads "
                   f"{last.gyro_mean:+.5f}")
        if abs(evidence["bias_estimate_rad_s"] - last.gyro_mean) > max(DISAGREE_RAD_S, 5.0 * last.spread):
            return Verdict(imu.name, "gyro_bias", "warn",
                           f"the bias estimate ({evidence['bias_estimate_rad_s']:+.5f} rad/s) is off what the gyro "
                           f"reads at rest ({last.gyro_mean:+.5f}) although the standstill updates were accepted: "
                           "they are weighted too little (gyro noise overstated)",
                           sensor_key(imu.name, "gyro_noise"), noise_hint, evidence)
    if not ch.n_nis:  # every update learned the bias (its prior still wide): no NIS to judge
        return Verdict(imu.name, "gyro_bias", "ok",
                       f"{ch.n} standstill bias updates, all while the bias was being learned: not judged against "
                       f"the stated noise{against}", evidence=evidence)
    return Verdict(imu.name, "gyro_bias", "ok",
                   f"standstill bias updates consistent ({ch.nis_per_dof:.2f} per dof over {ch.n} updates{against})",
                   evidence=evidence)
