"""A gyro bias learned late: the heading drifted until the first standstill, and whether the IMU's yaw could hold it.

With the gyro driving heading and nothing absolute to correct it (no GPS, no pose, the IMU's yaw
not fused), the gyro's z bias b is learned only at standstills. Until the first one the filter
integrates it with its prior (zero), so the heading turns by b x t, and the track with it: a race
car that sets off at once with b = 0.004 rad/s has turned 0.24 rad (14 deg) when it first stops a
minute later. The standstills measure b directly (the gyro at rest: ``gyro.rest_bias``, the figure every
check names, not the first standstill's alone, which can be a few noisy samples), so the drift is known
after the fact: |b| x (time until the core's first accepted bias update, T_b). With the odom frame
continuous (``filter.continuous_odom``, the default: REP-105) that update corrects the heading's rate
from then on and leaves the heading where the old bias bent it, so averaged over a run of T seconds
the heading is off by ~|b| T_b^2 / (2 T) + |b| T_b (T - T_b) / T. With ``continuous_odom = false`` it
also turns the heading back, through the covariance of heading and bias the filter built while
integrating (as far as the stated gyro noise lets it); the track driven in the meantime stays bent,
and the heading was off by ~|b| T_b^2 / (2 T).

Many IMUs publish a yaw of their own (an AHRS integrating its gyro with its own bias estimate). In
``roll_pitch`` mode it is not fused, yet it may be good: its yaw minus the gyro heading corrected by
the measured b drifts at the IMU's own rate r (fitted over windows of a minute, with the wander
left after a + r t + c gyro_heading, as ``heading.detrended_rms`` does for a fused yaw). Fused as a
``relative`` yaw it holds the heading from the start, but its drift then runs for the whole run:
off by ~|r| T / 2 on average. The advice is given when that is clearly the smaller (RELATIVE_MARGIN)
and the yaw does not wander (a magnetometer near motors); otherwise the verdict says to start at rest.
"""

from __future__ import annotations

import math

from ...core.sensors.registry import kind_of
from ..gyro import gyro_imu, quiet_episodes, rest_bias
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key
from ..heading import WANDER_RAD, imu_yaw_drift


__all__ = ["LateBias"]

LATE_DRIFT_RAD = 0.05  # heading drift before the first standstill worth a verdict (3 deg)
RELATIVE_MARGIN = 0.5  # the relative yaw's mean heading error must stay below this share of the late bias's


class LateBias(BaseCheck):
    """A gyro bias first learned late, after the heading drifted with it."""

    name = "late_bias"

    def run(self, ev: Evidence) -> list[Verdict]:
        """The verdict on a gyro bias first learned long after the start, without a heading reference (module doc).

        ``ch``: the IMU's gyro_bias channel. The bias counts as learned at its first accepted update (the core's
        own moment: it also waits out a coast, core/sensors/odom/model.py), or never; what it is, the gyro at rest
        says (``rest_bias``)."""
        series, cfg, gyro_fused, ch = ev.series, ev.config, ev.gyro_fused, ev.gyro_bias_stats
        imu = gyro_imu(cfg)
        if imu is None or not gyro_fused or len(series.odom_t) < 2:
            return []
        if any(kind_of(s).heading_reference(s) for s in cfg.sensors):
            return []  # a heading reference corrects the drift as it happens
        episodes, _ = quiet_episodes(series, cfg, imu)
        b = rest_bias(episodes)
        if not math.isfinite(b):
            return []  # never learned: bias_check's verdict
        first = episodes[0]
        t_start, t_end = series.odom_t[0], series.odom_t[-1]
        accepted = [t for t, rejected in zip(ch.stamps, ch.rejected_flags) if not rejected] if ch is not None else []
        before = (min(accepted) if accepted else t_end) - t_start
        drift = abs(b) * before
        if drift < LATE_DRIFT_RAD:
            return []
        evidence = {"first_standstill_s": first.t0 - t_start, "gyro_at_rest_rad_s": b, "heading_drift_rad": drift}
        unknown = f"for the first {before:.0f} s (its first accepted update)" if accepted else \
            f"for the whole run ({before:.0f} s)"
        where = (f"at its first standstill, {first.t0 - t_start:.0f} s in" if len(episodes) == 1 else
                 f"the median of its {len(episodes)} standstills, the first {first.t0 - t_start:.0f} s in")
        msg = (f"the gyro's z bias was unknown {unknown}: the gyro reads {b:+.4f} rad/s at rest ({where}), "
               "so until then the heading "
               f"turned by up to {drift:.2f} rad ({math.degrees(drift):.0f} deg) that the vehicle did not, and the "
               "track with it; nothing configured holds the heading (no GPS or pose, the IMU's yaw not fused). "
               + ("The odom frame being continuous (filter.continuous_odom), the heading stays off by that from then on"
                  if cfg.filter.continuous_odom else
                  "The bias update turns the heading back as far as the filter's correlations allow; the track driven "
                  "meanwhile stays bent"))
        own = imu_yaw_drift(series, cfg, imu)
        if own is not None:
            # the IMU's own drift against the bias-corrected gyro, r: the figure every check names
            wander, rate, _ = own
            run = t_end - t_start
            late_cost = abs(b) * before * before / (2.0 * run)  # mean heading error, as configured ...
            if cfg.filter.continuous_odom:  # ... plus the drift left in the heading after the update
                late_cost += abs(b) * before * max(run - before, 0.0) / run
            relative_cost = abs(rate) * run / 2.0  # ... with the IMU's yaw fused as relative
            evidence.update({"imu_yaw_wander_rad": wander, "imu_yaw_drift_rad_s": rate,
                             "mean_heading_error_rad": late_cost, "relative_mean_heading_error_rad": relative_cost})
            if wander < WANDER_RAD and relative_cost < RELATIVE_MARGIN * late_cost:
                return [Verdict(imu.name, "heading", "warn",
                                msg + f". The IMU's own yaw follows the bias-corrected gyro to {wander:.3f} rad rms "
                                f"and drifts {rate:+.5f} rad/s: fused as a relative yaw it holds the heading from "
                                f"the start, off by ~{relative_cost:.3f} rad on average over the run against "
                                f"~{late_cost:.3f} now", sensor_key(imu.name, "orientation"),
                                'orientation = "relative"', evidence)]
            if wander >= WANDER_RAD:
                msg += f". The IMU's own yaw would not do better: it wanders by {wander:.3f} rad rms"
            elif relative_cost >= late_cost:
                msg += (f". The IMU's own yaw would not do better: it drifts {rate:+.5f} rad/s, ~{relative_cost:.3f} "
                        f"rad off on average over the run against ~{late_cost:.3f} now")
            else:  # better on this estimate, not by the margin its confounders (the gyro's scale, a moving bias) need
                msg += (f". The IMU's own yaw, fused as relative (orientation = \"relative\"), would be off by "
                        f"~{relative_cost:.3f} rad on average over the run against ~{late_cost:.3f} now (it drifts "
                        f"{rate:+.5f} rad/s): better on this estimate, though not by the half it needs to be advised "
                        "without a heading reference to judge the two by")
        return [Verdict(imu.name, "heading", "warn", msg + ". Start recordings with the vehicle at rest for at least "
                        f"standstill_s ({cfg.filter.standstill_s:g} s) so that the bias is learned before it drives",
                        evidence=evidence)]
