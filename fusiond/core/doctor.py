"""The tuning doctor: innovation statistics turned into plain-words verdicts.

It encodes the table a practitioner tunes an EKF with. Each verdict names the
likely cause and the config key to change. It reads only diagnostics records,
odometry twists and the core's counters, so the same doctor serves the end of
`fusiond replay` and a live monitor fed from the diagnostics stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import msgspec

from ..config import Config, ImuSensor, OdomSensor
from .diagnostics import DiagnosticsRecord

NIS_HIGH = 2.0  # mean NIS per degree of freedom: R (or Q) understated by 2x or more
NIS_LOW = 0.3  # ... or overstated by 3x or more
MIN_UPDATES = 50
OFFSET_RAD = 0.01  # a mean roll/pitch innovation this large is a mounting error, not noise
SLIP_FRACTION = 0.2


class Verdict(msgspec.Struct):
    sensor: str
    channel: str
    level: str  # ok | warn | problem
    message: str
    key: str = ""  # the config key to change, when there is one


@dataclass
class ChannelStats:
    components: list[str]
    n: int = 0
    rejected: int = 0
    nis_sum: float = 0.0
    dof: int = 0
    sums: list[float] = field(default_factory=list)
    squares: list[float] = field(default_factory=list)
    variances: list[float] = field(default_factory=list)

    def add(self, r: DiagnosticsRecord) -> None:
        if r.components != self.components:
            return  # e.g. a yaw row missing from one message: keep the channel's shape
        if not self.sums:
            k = len(self.components)
            self.sums, self.squares, self.variances = [0.0] * k, [0.0] * k, [0.0] * k
        self.n += 1
        self.rejected += r.rejected
        if math.isfinite(r.nis):
            self.nis_sum += r.nis
            self.dof = r.dof
        for i, (y, v) in enumerate(zip(r.innovation, r.innovation_var)):
            self.sums[i] += y
            self.squares[i] += y * y
            self.variances[i] += v

    @property
    def nis_per_dof(self) -> float:
        return self.nis_sum / (self.n * self.dof) if self.n and self.dof else math.nan

    def component(self, i: int) -> tuple[float, float, float]:
        """(mean, rms, rms predicted by S) of component i."""
        n = max(self.n, 1)
        return self.sums[i] / n, math.sqrt(self.squares[i] / n), math.sqrt(self.variances[i] / n)


@dataclass
class TwistStats:
    n: int = 0
    abs_vx: float = 0.0
    abs_vy: float = 0.0
    abs_wz: float = 0.0


@dataclass
class TiltStats:
    """Estimated roll/pitch over the run: a steady lean on level ground is a mounting error."""

    n: int = 0
    sums: list[float] = field(default_factory=lambda: [0.0, 0.0])
    squares: list[float] = field(default_factory=lambda: [0.0, 0.0])


LEAN_RAD = 0.03  # a mean lean of ~1.7 degrees that barely varies


class Doctor:
    """``cfg`` may be None (a remote monitor that only sees the diagnostics stream): the
    sensors are then known by name only, and an orientation channel's mode is read
    from its components (a yaw row means absolute or relative)."""

    def __init__(self, cfg: Config | None) -> None:
        self.cfg = cfg if cfg is not None else Config()
        self.channels: dict[tuple[str, str], ChannelStats] = {}
        self.twist = TwistStats()
        self.tilt = TiltStats()

    def add(self, record: DiagnosticsRecord) -> None:
        key = (record.sensor, record.channel)
        ch = self.channels.get(key)
        if ch is None:
            ch = self.channels[key] = ChannelStats(list(record.components))
        ch.add(record)

    def add_twist(self, linear: tuple[float, float, float], angular: tuple[float, float, float]) -> None:
        t = self.twist
        t.n += 1
        t.abs_vx += abs(linear[0])
        t.abs_vy += abs(linear[1])
        t.abs_wz += abs(angular[2])

    def add_attitude(self, roll: float, pitch: float) -> None:
        t = self.tilt
        t.n += 1
        for i, a in enumerate((roll, pitch)):
            t.sums[i] += a
            t.squares[i] += a * a

    # -- verdicts ------------------------------------------------------------
    def verdicts(self, stats: dict[str, dict] | None = None, at_cap: bool = False,
                 covariance_resets: int = 0) -> list[Verdict]:
        """``stats``: per sensor {"received", "applied", "late", "dropped": {reason: n}}."""
        out: list[Verdict] = []
        sensors = {s.name: (i, s) for i, s in enumerate(self.cfg.sensors)}
        for (name, channel), ch in sorted(self.channels.items()):
            i, s = sensors.get(name, (-1, None))
            where = f"sensors[{i}]" if i >= 0 else name
            if ch.n < MIN_UPDATES:
                out.append(Verdict(name, channel, "ok", f"only {ch.n} updates: too few to judge"))
                continue
            if channel == "orientation":
                if not isinstance(s, ImuSensor):
                    mode = "absolute" if "yaw" in ch.components else "roll_pitch"
                    s = ImuSensor(name=name, key=name, orientation=mode)
                out.extend(self._orientation(name, where, s, ch))
            elif channel == "yaw_rate":
                out.extend(self._yaw_rate(name, where, ch))
            elif channel == "gyro_bias":
                out.extend(self._gyro_bias(name, where, ch))
            elif channel in ("position", "pose", "pose_delta"):
                out.extend(self._absolute(name, where, channel, ch))
        out.extend(self._lean(sensors))
        odom = next(((i, s) for i, s in enumerate(self.cfg.sensors) if isinstance(s, OdomSensor)), None)
        if odom is not None:
            out.extend(self._twist_frame(*odom))
        if stats:
            out.extend(self._drops(stats, sensors))
        if covariance_resets:
            out.append(Verdict("filter", "covariance", "problem",
                               f"covariance went non-finite {covariance_resets} time(s) and was reset: Q too large, "
                               "a time jump, or a bad Jacobian; check the stamps and filter.process_noise",
                               "filter.process_noise"))
        if at_cap:
            out.append(Verdict("filter", "covariance", "warn",
                               "position/attitude uncertainty reached filter.covariance_cap: long dropouts "
                               "(filter.gap_s, filter.gap_inflation) or too much process noise",
                               "filter.covariance_cap"))
        return out

    def _orientation(self, name: str, where: str, s: ImuSensor, ch: ChannelStats) -> list[Verdict]:
        out = []
        per_dof = ch.nis_per_dof
        comps = ch.components
        comp_nis = []
        for i in range(len(comps)):
            _, rms, pred = ch.component(i)
            comp_nis.append((rms / pred) ** 2 if pred > 0 else math.nan)
        detail = ", ".join(f"{c} rms {ch.component(i)[1]:.4f} vs {ch.component(i)[2]:.4f} predicted"
                           for i, c in enumerate(comps))
        if per_dof > NIS_HIGH:
            yaw_dominates = "yaw" in comps and comp_nis[comps.index("yaw")] > 3.0 * max(
                [v for c, v in zip(comps, comp_nis) if c != "yaw"] or [0.0])
            if yaw_dominates and s.orientation in ("absolute", "relative"):
                hint = ("IMU yaw disagrees with the predicted heading: a magnetometer-disturbed IMU yaw, or "
                        "(without the gyro) wheels whose yaw rate is wrong. Take heading from the gyro: "
                        f'{where}.orientation = "roll_pitch" with {where}.angular_velocity = true')
                out.append(Verdict(name, "orientation", "problem",
                                   f"NIS high ({per_dof:.1f} per dof; {detail}). {hint}", f"{where}.orientation"))
            else:
                sig = [round(ch.component(i)[1], 4) for i in range(len(comps))]
                out.append(Verdict(name, "orientation", "problem",
                                   f"NIS high ({per_dof:.1f} per dof; {detail}): the stated noise is too small "
                                   f"or the IMU lies; measured innovation rms suggests orientation_noise of about {sig}",
                                   f"{where}.orientation_noise"))
        elif per_dof < NIS_LOW:
            out.append(Verdict(name, "orientation", "warn",
                               f"NIS low ({per_dof:.2f} per dof; {detail}): the stated orientation noise is larger "
                               "than the innovations show (or the process noise is): the filter under-uses the IMU",
                               f"{where}.orientation_noise"))
        else:
            out.append(Verdict(name, "orientation", "ok", f"consistent ({per_dof:.2f} per dof)"))
        for i, c in enumerate(comps):
            mean, rms, _ = ch.component(i)
            if c in ("roll", "pitch") and abs(mean) > OFFSET_RAD and abs(mean) > 0.5 * rms:
                out.append(Verdict(name, "orientation", "warn",
                                   f"constant {c} offset of {mean:+.3f} rad in the innovations: a mounting "
                                   f"rotation not in the config", f"{where}.extrinsic_rpy"))
        return out

    def _yaw_rate(self, name: str, where: str, ch: ChannelStats) -> list[Verdict]:
        frac = ch.rejected / ch.n
        mean, rms, _ = ch.component(0)
        if frac > SLIP_FRACTION:
            return [Verdict(name, "yaw_rate", "warn",
                            f"wheel yaw rate disagrees with the gyro in {100 * frac:.0f}% of samples "
                            f"(mean {mean:+.3f}, rms {rms:.3f} rad/s): skid-steer slip or a driver offset. "
                            "The gyro drives heading, so this is only reported; without the gyro the heading "
                            "would follow the wheels", f"{where}.slip_threshold")]
        if abs(mean) > 0.02:
            return [Verdict(name, "yaw_rate", "warn",
                            f"wheel yaw rate offset of {mean:+.3f} rad/s against the gyro: a driver offset or "
                            "uncorrected gyro bias")]
        return [Verdict(name, "yaw_rate", "ok", f"wheels agree with the gyro (rms {rms:.3f} rad/s)")]

    def _gyro_bias(self, name: str, where: str, ch: ChannelStats) -> list[Verdict]:
        per_dof = ch.nis_per_dof
        frac = ch.rejected / ch.n
        if frac > 0.1:
            return [Verdict(name, "gyro_bias", "warn",
                            f"{100 * frac:.0f}% of standstill bias updates rejected: the robot turned while its "
                            "wheels read zero (pushed or carried), or the gyro noise is understated",
                            f"{where}.gyro_noise")]
        if per_dof > NIS_HIGH:
            return [Verdict(name, "gyro_bias", "warn",
                            f"standstill gyro NIS high ({per_dof:.1f} per dof): gyro noise understated",
                            f"{where}.gyro_noise")]
        return [Verdict(name, "gyro_bias", "ok", f"standstill bias updates consistent ({per_dof:.2f} per dof)")]

    def _absolute(self, name: str, where: str, channel: str, ch: ChannelStats) -> list[Verdict]:
        """GPS and pose channels: NIS against the stated noise (position_noise / orientation_noise)."""
        per_dof = ch.nis_per_dof
        frac = ch.rejected / ch.n
        key = f"{where}.position_noise"
        detail = ", ".join(f"{c} rms {ch.component(i)[1]:.3f}" for i, c in enumerate(ch.components))
        if frac > 0.1:
            return [Verdict(name, channel, "warn",
                            f"{100 * frac:.0f}% of updates gated ({detail}): the sensor jumps (multipath, "
                            "relocalisation) or its noise is understated", f"{where}.mahalanobis_threshold")]
        if per_dof > NIS_HIGH:
            return [Verdict(name, channel, "problem",
                            f"NIS high ({per_dof:.1f} per dof; {detail}): the stated noise is too small, a "
                            "mounting offset (extrinsic_xyz) is missing, or an odometry scale error is "
                            "unmodelled (scale_estimation)", key)]
        if per_dof < NIS_LOW:
            return [Verdict(name, channel, "warn",
                            f"NIS low ({per_dof:.2f} per dof; {detail}): the stated noise is larger than the "
                            "innovations show", key)]
        return [Verdict(name, channel, "ok", f"consistent ({per_dof:.2f} per dof)")]

    def _lean(self, sensors: dict) -> list[Verdict]:
        t = self.tilt
        imu = next(((i, s) for i, s in sensors.values() if isinstance(s, ImuSensor)), None)
        if t.n < MIN_UPDATES or imu is None:
            return []
        out = []
        for k, name in enumerate(("roll", "pitch")):
            mean = t.sums[k] / t.n
            std = math.sqrt(max(t.squares[k] / t.n - mean * mean, 0.0))
            if abs(mean) > LEAN_RAD and std < 0.5 * abs(mean):
                out.append(Verdict(imu[1].name, "attitude", "warn",
                                   f"the robot leans by {mean:+.3f} rad in {name} on average (std {std:.3f}): "
                                   "on level ground that is an IMU mounting rotation missing from, or wrong in, "
                                   "the config (the body-frame twist then climbs or sinks)",
                                   f"sensors[{imu[0]}].extrinsic_rpy"))
        return out

    def _twist_frame(self, i: int, s: OdomSensor) -> list[Verdict]:
        t = self.twist
        if t.n < MIN_UPDATES or t.abs_vx + t.abs_vy < 1e-6:
            return []
        lateral = t.abs_vy / max(t.abs_vx + t.abs_vy, 1e-12)
        if s.twist_frame == "world" and lateral < 0.05 and t.abs_wz / t.n > 0.05:
            return [Verdict(s.name, "twist", "problem",
                            "twist configured in the world frame, but its lateral velocity stays near zero while "
                            "the robot turns: it is a body-frame twist, and the trajectory heading will run away",
                            f"sensors[{i}].twist_frame")]
        if s.twist_frame == "body" and lateral > 0.35:
            return [Verdict(s.name, "twist", "warn",
                            f"lateral velocity is {100 * lateral:.0f}% of the motion: a wheeled robot's body twist "
                            "has little; if the driver reports the twist in the odom frame, say so",
                            f"sensors[{i}].twist_frame")]
        return []

    def _drops(self, stats: dict[str, dict], sensors: dict) -> list[Verdict]:
        out = []
        for name, st in stats.items():
            received = max(st.get("received", 0), 1)
            dropped = st.get("dropped", {})
            old = dropped.get("too_old", 0)
            if old / received > 0.01:
                out.append(Verdict(name, "time", "warn",
                                   f"{old} samples ({100 * old / received:.1f}%) arrived older than the history: "
                                   "their sensor's stamps lag more than filter.history_s", "filter.history_s"))
            bad = {k: v for k, v in dropped.items() if k != "too_old"}
            if bad:
                reasons = ", ".join(f"{k}={v}" for k, v in sorted(bad.items()))
                out.append(Verdict(name, "input", "warn", f"dropped samples: {reasons}"))
        return out


def format_verdicts(verdicts: list[Verdict]) -> str:
    marks = {"ok": "ok     ", "warn": "WARN   ", "problem": "PROBLEM"}
    lines = []
    for v in verdicts:
        key = f"  [{v.key}]" if v.key else ""
        lines.append(f"doctor {marks[v.level]} {v.sensor}/{v.channel}: {v.message}{key}")
    return "\n".join(lines)
