"""The whole-run checks: the vehicle's attitude and mounting, logging gaps, coasting, the twist's frame,
the covariance, and what the core counted (drops, clocks, resets).

The attitude, gap and coasting checks speak of one IMU (``Evidence.run_imu``); all but the core's
counters need the config.
"""

from __future__ import annotations

import math

from ..core.layout import state_layout
from .attitude import lean_verdict, mount_verdict
from .check import BaseCheck, found
from .clock import ClockOffsets, clock_verdicts
from .coast import coast_verdict
from .covariance import cap_verdict
from .evidence import Evidence
from .gap_heading import gap_heading_verdict
from .grade import grade_fit, grade_verdict
from .gyro import bias_check, quiet_episodes
from .late_bias import late_bias_verdict
from .thresholds import MIN_UPDATES
from .twist import twist_frame_verdict
from .verdict import Verdict, filter_key

__all__ = ["GyroBiasUnseen", "Lean", "Mounting", "GapHeading", "LateBias", "Coast", "TwistFrame", "CovarianceCap",
           "Drops", "Clocks", "CovarianceResets"]


class GyroBiasUnseen(BaseCheck):
    """The gyro bias when no standstill update was ever made (no gyro-bias channel)."""

    name = "gyro_bias_unseen"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.gyro_bias_stats is not None:
            return []
        return found(bias_check(ev.series, ev.config, None, ev.gyro_fused, ev.stats))


class Lean(BaseCheck):
    """The estimate's lean: against the grade the GPS altitude measures when there is enough driving to
    tell (it replaces "on level ground"), else its mean over the run."""

    name = "lean"

    def run(self, ev: Evidence) -> list[Verdict]:
        graded = grade_verdict(grade_fit(ev.series, ev.config), ev.run_imu, ev.mount,
                               state_layout(ev.config).has("twist_pitch"))
        return found(graded if graded is not None else lean_verdict(ev.tilt, ev.run_imu, MIN_UPDATES, ev.mount))


class Mounting(BaseCheck):
    """The IMU's mounting yaw the accelerometer measures against the wheels."""

    name = "mounting"
    listed_after = ("lean",)  # both speak of the IMU's attitude: the lean first

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(mount_verdict(ev.run_imu, ev.mount, ev.tilt, MIN_UPDATES))


class GapHeading(BaseCheck):
    """The IMU's yaw against the estimate's across logging gaps."""

    name = "gap_heading"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(gap_heading_verdict(ev.series, ev.config, ev.run_imu, ev.t0))


class LateBias(BaseCheck):
    """A gyro bias first learned late, after the heading drifted with it."""

    name = "late_bias"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(late_bias_verdict(ev.series, ev.config, ev.gyro_fused, ev.gyro_bias_stats))


class Coast(BaseCheck):
    """How the vehicle slowed while its drive read zero, against the configured coast-down."""

    name = "coast"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.run_imu is None:
            return []
        standstills, turning = quiet_episodes(ev.series, ev.config, ev.run_imu)
        return found(coast_verdict(ev.series, ev.config, ev.mount, turning, standstills))


class TwistFrame(BaseCheck):
    """Whether the odometry twist is in the frame the config says (body or world)."""

    name = "twist_frame"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.odom is None:
            return []
        return found(twist_frame_verdict(ev.odom, ev.twist, MIN_UPDATES))


class CovarianceCap(BaseCheck):
    """A covariance left at its cap: what kept it growing."""

    name = "covariance_cap"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(cap_verdict(ev.series, ev.config, ev.at_cap, ev.gyro_fused, ev.standstill_updates, ev.stats))


class Drops(BaseCheck):
    """Samples the core dropped: too old for the history, or for another reason."""

    name = "drops"
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        return _drops(ev.stats, ev.clocks) if ev.stats else []


class Clocks(BaseCheck):
    """Samples dropped as far from filter time, explained by their sensor's clock."""

    name = "clocks"
    listed_after = ("drops",)  # both speak of a sensor's time: the drops first
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        if not ev.stats or ev.clocks is None:
            return []
        return clock_verdicts(ev.stats, ev.clocks, ev.sensors)


class CovarianceResets(BaseCheck):
    """A covariance that went non-finite and was reset."""

    name = "covariance_resets"
    listed_after = ("covariance_cap",)  # both speak of the covariance: the cap first
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        n = ev.covariance_resets
        if not n:
            return []
        return [Verdict("filter", "covariance", "problem",
                        f"covariance went non-finite {n} time(s) and was reset: Q too large, a time jump, "
                        "or a bad Jacobian; check the stamps and filter.process_noise", filter_key("process_noise"))]


def _drops(stats: dict[str, dict], clocks: ClockOffsets | None = None) -> list[Verdict]:
    out = []
    for name, st in stats.items():
        received = max(st.get("received", 0), 1)
        dropped = st.get("dropped", {})
        old = dropped.get("too_old", 0)
        if old / received > 0.01:
            msg = (f"{old} samples ({100 * old / received:.1f}%) arrived older than the history: "
                   "their sensor's stamps lag more than filter.history_s")
            line = ""
            lag = clocks.lag(name) if clocks is not None else None
            if lag is not None and lag > 0.0:
                # the history must reach back over the lag of 99 % of the samples, with a fifth to spare
                line = f"history_s = {math.ceil(12.0 * lag) / 10.0:g}"
                msg += (f" (99% of them arrive within {lag:.2f} s of the other sensors' newest stamp). Each such "
                        "sample re-applies that much history; a lag this steady may be the sensor's clock (a stamp "
                        "set late or early), which a longer history only hides: check its driver's stamping")
            out.append(Verdict(name, "time", "warn", msg, filter_key("history_s"), line))
        bad = {k: v for k, v in dropped.items() if k != "too_old"}
        if bad:
            reasons = ", ".join(f"{k}={v}" for k, v in sorted(bad.items()))
            out.append(Verdict(name, "input", "warn", f"dropped samples: {reasons}"))
    return out
