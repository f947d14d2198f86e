"""The smoother through the fusion core on a simulated GPS robot with known truth (tests/support/sim_gps.py).

- Late data: the samples delivered as a transport would (each sensor lagging by its own delay, so the core
  rewinds its history again and again) give the same smoothed trajectory as the samples in stamp order: the
  record follows the final forward pass, never a timeline a rewind abandoned.
- After the fact the smoothed track is closer to the truth than the causal one, and at the last publish
  moment it is the filter's own estimate; in two-D mode too, exactly planar.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.estimator import rotation as rot
from fusiond.replay.run import run_samples

from tests.support.configs import robot_config
from tests.support.sim import arrival_order
from tests.support.sim_gps import World, simulate


def _world() -> World:
    return World(duration=50.0, odom_rate=20.0, imu_rate=50.0, speed=2.0, gps_rate=1.0, gps_sigma=0.8,
                 start=(0.0, 0.0, 1.0), seed=9)


def _config():
    return robot_config(gps="datum = [48.137, 11.575, 520.0]\n")


def _rms_after_heading(w: World, r, track: np.ndarray) -> float:
    """RMS horizontal error against the truth at the poses after the first one published with its heading
    known (before it the GPS heading search publishes a placeholder, kept as it is)."""
    truth = {round(t, 6): (x, y) for t, x, y, _ in w.truth}
    causal = np.asarray(r.trajectory).reshape(-1, 8)
    t_known = causal[np.argmax(np.asarray(r.heading_known, dtype=bool)), 0]
    errs = [math.hypot(x - truth[round(t, 6)][0], y - truth[round(t, 6)][1])
            for t, x, y in track[:, 0:3] if t > t_known and round(t, 6) in truth]
    assert len(errs) > 500
    return math.sqrt(sum(e * e for e in errs) / len(errs))


@pytest.mark.parametrize("lag", [{"imu": 0.03, "gps": 0.25}, {"imu": 0.25, "wheel": 0.1}],
                         ids=["fixes late", "imu late: rewinds re-apply fixes and their heading fits"])
def test_late_data_gives_the_same_smoothed_trajectory_as_data_in_order(lag):
    samples = simulate(_world())
    cfg = _config()
    in_order = run_samples(samples, cfg, smooth=True)
    late = arrival_order(samples, lag, jitter=0.02, seed=4)
    assert late != samples
    rewound = run_samples(late, cfg, smooth=True)
    assert sum(st.late for st in rewound.core.stats) > 100  # the core did rewind, many times
    a = np.asarray(in_order.smoothed).reshape(-1, 8)
    b = np.asarray(rewound.smoothed).reshape(-1, 8)
    assert a.shape == b.shape and a.shape[0] > 500
    np.testing.assert_array_equal(a[:, 0], b[:, 0])
    np.testing.assert_allclose(a[:, 1:], b[:, 1:], rtol=0, atol=1e-9)


def test_smoothed_track_is_closer_to_the_truth_and_ends_on_the_filter():
    w = _world()
    samples = simulate(w)
    r = run_samples(samples, _config(), smooth=True)
    causal = np.asarray(r.trajectory).reshape(-1, 8)
    smoothed = np.asarray(r.smoothed).reshape(-1, 8)
    assert _rms_after_heading(w, r, smoothed) < 0.8 * _rms_after_heading(w, r, causal)
    # in stamp order the last odometry message is published at its own stamp: the last smoothed pose is
    # that published one, to the bit
    assert smoothed[-1].tolist() == causal[-1].tolist()


def test_two_d_mode_smoothed_stays_planar_and_beats_the_filter():
    """Two-D mode holds z, roll and pitch at 0 after every step (``hold_planar``): recorded as corrections
    of those components, the smoothed poses stay exactly planar."""
    w = _world()
    r = run_samples(simulate(w), robot_config(gps="datum = [48.137, 11.575, 520.0]\n", filt="two_d_mode = true"),
                    smooth=True)
    smoothed = np.asarray(r.smoothed).reshape(-1, 8)
    causal = np.asarray(r.trajectory).reshape(-1, 8)
    assert np.all(smoothed[:, 3] == 0.0) and np.all(smoothed[:, 4:6] == 0.0)
    assert _rms_after_heading(w, r, smoothed) < 0.8 * _rms_after_heading(w, r, causal)


def test_poses_of_the_heading_search_are_turned_by_the_heading_found_later():
    """While the GPS searches for the heading the daemon publishes a position near the newest fix (the
    state dead-reckons from it along a placeholder heading). After the fact the fits that came later give
    that heading: the smoothed pose is the fix's position plus the displacement turned by them."""
    w = World(duration=50.0, odom_rate=20.0, imu_rate=50.0, speed=10.0, gps_rate=1.0, gps_sigma=0.8,
              start=(0.0, 0.0, 1.0), seed=9)
    r = run_samples(simulate(w), _config(), smooth=True)
    assert len(r.core._smoothing.turns) >= 2  # a provisional fit, then the one that makes the heading known
    truth = {round(t, 6): (x, y) for t, x, y, _ in w.truth}
    causal = np.asarray(r.trajectory).reshape(-1, 8)
    smoothed = np.asarray(r.smoothed).reshape(-1, 8)
    t_known = causal[np.argmax(np.asarray(r.heading_known, dtype=bool)), 0]

    def rms_searching(track: np.ndarray) -> float:
        errs = [math.hypot(x - truth[round(t, 6)][0], y - truth[round(t, 6)][1])
                for t, x, y in track[:, 0:3] if t < t_known and round(t, 6) in truth]
        assert len(errs) > 50
        return math.sqrt(sum(e * e for e in errs) / len(errs))

    assert rms_searching(smoothed) < 0.5 * rms_searching(causal)


def test_the_heading_of_the_searchs_poses_is_turned_with_their_positions():
    """The poses published during the heading search carry the placeholder heading (the fit has not come yet):
    smoothed, their attitude turns with their position by the heading found later, so that the smoothed
    trajectory does not point the wrong way for its first seconds (a car heading north read east in the TUM)."""
    w = World(duration=50.0, odom_rate=20.0, imu_rate=50.0, speed=10.0, gps_rate=1.0, gps_sigma=0.8,
              start=(0.0, 0.0, 1.0), seed=9)
    r = run_samples(simulate(w), _config(), smooth=True)
    truth = {round(t, 6): yaw for t, _, _, yaw in w.truth}
    causal = np.asarray(r.trajectory).reshape(-1, 8)
    smoothed = np.asarray(r.smoothed).reshape(-1, 8)
    t_known = causal[np.argmax(np.asarray(r.heading_known, dtype=bool)), 0]

    def worst_searching(track: np.ndarray) -> float:
        errs = [abs(rot.wrap(rot.yaw(tuple(q)) - truth[round(t, 6)])) for t, q in zip(track[:, 0], track[:, 4:8])
                if w.truth[0][0] + 3.0 < t < t_known and round(t, 6) in truth]  # driving, heading still searched
        assert len(errs) > 20
        return max(errs)

    assert worst_searching(causal) > 0.5  # the placeholder: 1 rad off the truth
    assert worst_searching(smoothed) < 0.1
