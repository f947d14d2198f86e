"""A robot_localization config migrated with its process noise carried over (docs/MIGRATION.md says not to): on the
Jackal bag (robot_localization's own test bag, in data/), the doctor names filter.process_noise, not a sensor's
noise, and its line brings the estimate back to where robot_localization's own filter ends."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BAG = ROOT / "data" / "jackal_test2.bag"
RL_FINAL = (1.0206, 3.4292, 0.7419)  # robot_localization's EKF on this bag (its test suite)
RL_TOLERANCE = 0.1383  # ... and its test's tolerance
# a robot_localization process_noise_covariance (x 0.03, yaw 0.06 on its diagonal) carried over as sqrt(q)
CARRIED = "process_noise = [0.1732, 0.2449]"

pytestmark = pytest.mark.e2e


def test_a_carried_over_process_noise_is_named_and_its_line_holds_the_estimate():
    from fusiond.config import loads
    from fusiond.replay.run import replay
    from fusiond.tune.advice import with_suggestion

    text = (ROOT / "examples" / "jackal_rl.toml").read_text()
    assert "[filter]" not in text  # the example states no filter table: the carried-over one is the only one
    cfg = loads(f"[filter]\n{CARRIED}\n" + text)
    result = replay([BAG], cfg, keep_trace=False, progress=False)
    (v,) = [v for v in result.verdicts() if v.key == "filter.process_noise"]
    assert (v.sensor, v.channel) == ("imu", "orientation") and "no orientation_noise brings the NIS up" in v.message
    position, attitude = (float(x) for x in re.findall(r"[\d.e-]+", v.suggestion.split("=", 1)[1]))
    assert position == 0.1732 and 0.0 < attitude < 0.2449 / 10.0, v.suggestion
    pasted, _ = with_suggestion(cfg, v)
    after = replay([BAG], pasted, keep_trace=False, progress=False, doctor=False)
    before_d, after_d = (math.dist(r.final[1:4], RL_FINAL) for r in (result, after))
    assert after_d < RL_TOLERANCE and after_d <= before_d + 0.005, (before_d, after_d)
