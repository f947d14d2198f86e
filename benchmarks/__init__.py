"""fusiond's benchmarks: measurement code of the source tree, not part of the installed package.

`bench` times the estimator, the core and a replay on a bag; `bench_latency` measures sensor put -> fused
pose over Zenoh and the daemon's CPU beside a bare subscriber. They run from a clone: `fusiond bench` and
`fusiond bench-latency` import them from the source tree fusiond runs from (fusiond/cli/benchmarks.py),
and the scripts under scripts/ and the tests import them as ``benchmarks.*``.
"""

__all__ = ["bench", "bench_latency"]
