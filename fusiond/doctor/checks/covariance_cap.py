"""Why the covariance reached its cap: dropouts, an unobservable state, or process noise.

Each cause has its own fix, so the verdict tells them apart from the series:
long silences of the odometry (the gap inflation did it), a gyro bias that was
never learned (no standstill and no heading reference: the bias uncertainty
integrates into heading and, at speed, into position), or else the process noise.
"""

from __future__ import annotations

from ..check import BaseCheck
from ..evidence import Evidence
from ..gyro import has_heading_reference
from ..verdict import Verdict, filter_key


__all__ = ["CovarianceCap"]

# a cap reached after dropouts is blamed on them (gap_inflation) when one silence lasted 10 s or they add up
# to a tenth of the run; shorter, rarer silences leave the growth to the dead-reckoning between them
DROPOUT_LONGEST_S = 10.0
DROPOUT_FRACTION = 0.1


class CovarianceCap(BaseCheck):
    """A covariance left at its cap: what kept it growing."""

    name = "covariance_cap"

    def run(self, ev: Evidence) -> list[Verdict]:
        """The covariance reached its cap: after dropouts, or because the gyro bias is unobservable (no
        standstill, no heading reference that delivered a sample: a configured sensor that stayed silent,
        replayed with --allow-missing, references nothing), or otherwise."""
        series, cfg, at_cap, stats = ev.series, ev.config, ev.at_cap, ev.stats
        fc = cfg.filter
        pos_cap, att_cap = fc.covariance_cap
        reached = at_cap or any(v >= 0.999 * pos_cap for v in series.est_pos_var) or any(
            v >= 0.999 * att_cap for v in series.est_att_var)
        if not reached:
            return []
        t = series.odom_t
        duration = t[-1] - t[0] if len(t) > 1 else 0.0
        gaps = series.odom_gaps
        longest = max((g[1] for g in gaps), default=0.0)
        total = sum(g[1] for g in gaps)
        # when it reached the cap for the last time (a start-up at the cap, before the first measurements, is not it)
        capped = [v >= 0.999 * pos_cap for v in series.est_pos_var]
        first_cap = next((series.est_t[i] for i in range(len(capped) - 1, -1, -1)
                          if capped[i] and (i == 0 or not capped[i - 1])), None)
        when = f" (from {first_cap - t[0]:.0f} s)" if first_cap is not None and t else ""
        # the dropouts are the cause only of a cap reached after the first of them began (a gyro stating 1e6 rad/s
        # of noise took the F1/10 to its cap at 80 s, 36 s before its first gap)
        after_gap = first_cap is None or first_cap >= min(g[0] for g in gaps) if gaps else False
        if after_gap and (longest >= DROPOUT_LONGEST_S or (duration > 0 and total >= DROPOUT_FRACTION * duration)):
            return [Verdict("filter", "covariance", "warn",
                            f"position/attitude uncertainty reached filter.covariance_cap{when} after dropouts: "
                            f"{len(gaps)} odometry silences longer than gap_s, {total:.1f} s in all, the longest "
                            f"{longest:.1f} s; each inflates the covariance by gap_inflation per sqrt(s)",
                            filter_key("gap_inflation"), evidence={"gaps": float(len(gaps)), "gap_total_s": total,
                                                                  "gap_longest_s": longest})]
        heading_ref = has_heading_reference(cfg, stats)
        if ev.gyro_fused and ev.standstill_updates == 0 and not heading_ref:
            return [Verdict("filter", "covariance", "warn",
                            f"position uncertainty reached filter.covariance_cap{when} because the gyro bias is "
                            f"unobservable: no standstill in {duration:.0f} s and no heading reference, so its initial "
                            f"uncertainty ({fc.gyro_bias_sigma:g} rad/s) integrates into heading "
                            f"({fc.gyro_bias_sigma:g} "
                            f"x {duration:.0f} s = {fc.gyro_bias_sigma * duration:.2f} rad) and, with speed, into "
                            "position. Not a dropout nor the process noise: state the bias spread measured at rest "
                            "(`fusiond calibrate-imu`), stop now and then, or add a heading reference",
                            filter_key("gyro_bias_sigma"),
                            evidence={"duration_s": duration, "standstill_updates": 0.0})]
        return [Verdict("filter", "covariance", "warn",
                        f"position/attitude uncertainty reached filter.covariance_cap{when} "
                        + (f"before the first odometry silence longer than gap_s ({min(g[0] for g in gaps) - t[0]:.0f} s)"
                           if gaps and not after_gap else f"without long dropouts (longest silence {longest:.1f} s)")
                        + " or an unobservable bias: the process noise (the gyro's stated noise among it, where the "
                        "gyro drives the attitude) grows it faster than the sensors constrain it",
                        filter_key("process_noise"))]
