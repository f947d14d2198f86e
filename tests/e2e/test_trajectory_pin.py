"""The trajectory pin: the Jackal bag's estimates must not move under a refactor or a speed-up.

A fresh replay of the shared Jackal bag through FusionCore, with the robot_localization-like
config (examples/jackal_rl.toml) and the recommended one (examples/jackal.toml), is compared
pose by pose with tests/data/jackal_pin.json, on each estimator backend (the Python reference and the
compiled kernels): every 50th published pose and the final one, to
1e-9 m in position, 1e-9 rad in attitude and 1e-9 in the position/attitude sigmas, and the
per-sensor counters exactly. The pin stores 12 decimals, so 1e-9 leaves room only for
floating-point reordering (a few ulps amplified over ~6000 steps), never for a changed model.

A deliberate behaviour change (an estimation issue, a new default) regenerates the pin with
`python tests/data/regen_jackal_pin.py` in its own commit, whose message states the reason.
"""

from __future__ import annotations

import json
import math

import pytest

from tests.support.jackal_pin import CONFIGS, PIN_PATH, trajectory

TOL = 1e-9  # m, rad, and sigma units


def _angle(q1: list[float], q2: list[float]) -> float:
    """Rotation angle of q1^-1 q2 (x y z w), from its vector part: acos of the dot product
    would turn a 1e-13 rounding into 1e-6 rad. q and -q are the same attitude."""
    x1, y1, z1, w1 = q1
    x2, y2, z2, w2 = q2
    w = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
    v = (w1 * x2 - x1 * w2 - y1 * z2 + z1 * y2, w1 * y2 - y1 * w2 - z1 * x2 + x1 * z2,
         w1 * z2 - z1 * w2 - x1 * y2 + y1 * x2)
    return 2.0 * math.atan2(math.hypot(*v), abs(w))


@pytest.fixture(scope="module")
def pin() -> dict:
    return json.loads(PIN_PATH.read_text())


def test_pin_file_covers_every_pinned_config(pin):
    assert sorted(pin) == sorted(CONFIGS)
    for run in pin.values():
        # every 50th of the published poses plus the final one (when not already a 50th)
        n, every = run["meta"]["published"], run["meta"]["every"]
        assert len(run["poses"]) == (n - 1) // every + 1 + (1 if (n - 1) % every else 0)


@pytest.mark.parametrize("config", CONFIGS)
def test_jackal_trajectory_matches_pin(jackal_bag, pin, config, backend):
    now = trajectory(jackal_bag, config, backend)
    ref = pin[config]
    assert now["published"] == ref["meta"]["published"]
    assert now["counters"] == ref["meta"]["counters"]
    assert now["covariance_resets"] == ref["meta"]["covariance_resets"]
    assert len(now["poses"]) == len(ref["poses"])
    worst_p = worst_q = worst_s = 0.0
    for a, b in zip(now["poses"], ref["poses"]):
        assert a[0] == pytest.approx(b[0], abs=1e-9), "published at a different stamp"
        worst_p = max(worst_p, math.dist(a[1:4], b[1:4]))
        worst_q = max(worst_q, _angle(a[4:8], b[4:8]))
        worst_s = max(worst_s, max(abs(u - v) for u, v in zip(a[8:14], b[8:14])))
    assert worst_p <= TOL, f"position moved by {worst_p:.3e} m"
    assert worst_q <= TOL, f"attitude moved by {worst_q:.3e} rad"
    assert worst_s <= TOL, f"a sigma moved by {worst_s:.3e}"
