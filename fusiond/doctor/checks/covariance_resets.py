"""A covariance that went non-finite and was reset (the core's counter)."""

from __future__ import annotations

from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, filter_key

__all__ = ["CovarianceResets"]


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
