"""A receiver whose error steps: the new level is taken within a few fixes, outliers are not.

Simulated car (tests/support/sim_gps.py) at 10 m/s with 10 Hz fixes of 0.5 m white noise per axis, stated
honestly, through the real fusion core. 60 s in, the heading long known, the fixes are edited: a step (every
later fix moved by 7 m: the receiver's error stepped and stays), or a burst (a few fixes moved, then back).
The sequential test and its threshold are in core/sensors/gps/model.py (module doc, "Steps"): at the default
false-alarm rate 1e-3 a step needs 1 + ceil(log(1000) / log(1 / BURST_REPEAT)) = 6 fixes, so a step is taken
at its 6th fix (0.5 s) and a burst of up to 5 fixes at one offset stays rejected.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.gps import BURST_REPEAT
from fusiond.core.sensors import GpsSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at

EARTH_RADIUS = 6378137.0
STEP_AT = 1060.0  # stamp of the first edited fix (sim stamps start at 1000 s)
SIGMA = 0.5


def _config(extra: str = ""):
    return robot_config(gps=f"datum = [48.137, 11.575, 520.0]\n{extra}")


def _car(**kw) -> World:
    base = dict(duration=75.0, odom_rate=50.0, imu_rate=100.0, speed=10.0, gps_rate=10.0, gps_sigma=SIGMA,
                start=(0.0, 0.0, 2.0), seed=11)
    base.update(kw)
    return World(**base)


def _moved(s: GpsSample, east: float, north: float) -> GpsSample:
    lat = s.latitude + math.degrees(north / EARTH_RADIUS)
    lon = s.longitude + math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(lat))))
    return msgspec.structs.replace(s, latitude=lat, longitude=lon)


def _edited(samples: list, offsets: list[tuple[float, float]] | None, step: tuple[float, float] | None = None) -> list:
    """From STEP_AT on: the k-th fix moved by ``offsets[k]`` (a burst), or every fix by ``step``."""
    out, k = [], 0
    for s in samples:
        if isinstance(s, GpsSample) and s.stamp >= STEP_AT - 1e-9:
            if step is not None:
                s = _moved(s, *step)
            elif k < len(offsets):
                s = _moved(s, *offsets[k])
            k += 1
        out.append(s)
    return out


def _run(w: World, samples: list, cfg, shift: tuple[float, float] = (0.0, 0.0)):
    """Fuse; the horizontal GPS records from STEP_AT on, and the published error against the truth moved
    by ``shift`` from STEP_AT on (the level the fixes say), per published stamp."""
    core = FusionCore(cfg)
    records, errors, heading_lost = [], [], False
    for s in samples:
        step = core.ingest(s)
        records += [r for r in step.records if r.sensor == "gps" and r.channel != "altitude" and r.stamp >= STEP_AT - 1e-9]
        if s.stamp >= STEP_AT - 5.0 and not core.heading_known:
            heading_lost = True
        if step.publish and core.pose()[0] >= STEP_AT - 1.0:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            if t >= STEP_AT - 1e-9:
                tx, ty = tx + shift[0], ty + shift[1]
            errors.append((t, math.hypot(x[0] - tx, x[1] - ty)))
    return core, records, errors, heading_lost


def test_the_minimum_run_follows_from_the_stated_rate():
    """The fewest fixes a step can be taken at, from the cap of one fix's evidence (module doc): 6 at 1e-3."""
    assert 1 + math.ceil(math.log(1e3) / math.log(1.0 / BURST_REPEAT)) == 6


def test_a_7_m_step_of_the_receiver_error_is_taken_at_its_sixth_fix_and_the_heading_stays():
    """Every fix from 60 s on is 7 m east (14 sigma: the gate rejects them). The step is taken at the 6th of
    them (0.5 s), not after REACQUIRE_JUMP_S (10 s, 70 m of driving at the wrong level); the position moves
    by the run's mean offset (6 fixes of 0.5 m: 0.2 m), the heading stays known (no new search) and from
    then on the fixes are accepted. 1 s after the step the estimate is where the new level says, within
    3 sigma of one fix."""
    w = _car()
    samples = _edited(simulate(w), None, step=(7.0, 0.0))
    core, records, errors, heading_lost = _run(w, samples, _config(), shift=(7.0, 0.0))
    channels = [r.channel for r in records]
    k = channels.index("position_step")
    assert k == 5  # the 6th fix of the step: 5 rejected before it
    assert all(r.rejected for r in records[:5])
    assert channels.count("position_step") == 1 and "position_reacquired" not in channels  # a step, not a loss
    after = records[k + 1:]
    assert sum(r.rejected for r in after) <= 0.01 * len(after)  # the gate's own few: the new level is fused
    assert not heading_lost and core.heading_known
    assert max(e for t, e in errors if t >= STEP_AT + 1.0) < 3 * SIGMA


def test_the_doctor_names_the_receivers_step_not_the_motion_model():
    """The 7 m step above, through the doctor: its verdict on the step says the receiver stepped, by how much
    and which way (the step fix's innovation, 7 m east within the fixes' noise and the few fixes the filter
    moved meanwhile: 1 m allowed), and that the wheels and the IMU did not cause it. No verdict says the
    filter lost the GPS (which points the user at the wheels' and the IMU's keys)."""
    from tests.support.verdicts import one, verdicts_of

    w = _car()
    verdicts = verdicts_of(_config(), _edited(simulate(w), None, step=(7.0, 0.0)))
    v = one(verdicts, "gps", "position_step")
    assert v.level == "warn" and not v.suggestion and "did not cause it" in v.message, v
    assert abs(v.evidence["largest_step_east_m"] - 7.0) < 1.0 and abs(v.evidence["largest_step_north_m"]) < 1.0, v
    assert v.evidence["steps"] == 1.0
    assert not [u for u in verdicts if u.channel == "position_reacquired"]


def test_the_doctor_names_a_burst_that_came_back_and_the_key_that_stops_following_one():
    """12 fixes at one 7 m offset, then back (the burst the test below follows and leaves): two steps 0.6-0.8 s
    apart that undo each other. The doctor names it a burst, says it was followed, and names step_false_alarm
    with what 0 and 1e-6 do, without a paste line (no replay without a reference can judge it)."""
    from tests.support.verdicts import one, verdicts_of

    w = _car()
    v = one(verdicts_of(_config(), _edited(simulate(w), [(7.0, 0.0)] * 12)), "gps", "position_step")
    assert v.level == "warn" and "came back 1 time(s)" in v.message and "followed" in v.message, v
    assert v.key == "sensors.gps.step_false_alarm" and not v.suggestion, v
    assert abs(v.evidence["largest_burst_m"] - 7.0) < 1.0 and 0.5 <= v.evidence["largest_burst_s"] <= 1.0, v


@pytest.mark.parametrize("offsets", [
    [(7.0, 0.0)] * 3,  # one jump for 3 fixes, then back
    [(7.0, 0.0), (0.0, -12.0), (-9.0, 5.0)],  # three outliers in different directions and sizes
    [(25.0, 0.0)] * 5,  # one large jump for 5 fixes (0.5 s), then back: the longest burst the test must reject
    [(7.0, 0.0), (7.4, 0.5), (0.0, 15.0), (6.8, -0.3), (7.2, 0.2)],  # a step-like run broken by an outlier
])
def test_outlier_bursts_stay_rejected(offsets):
    """A burst of outliers, whatever its shape up to 5 fixes, is rejected fix by fix and the estimate stays
    with the truth (within 3 sigma of one fix), nothing re-acquired."""
    w = _car()
    samples = _edited(simulate(w), offsets)
    _, records, errors, _ = _run(w, samples, _config())
    burst = records[:len(offsets)]
    assert all(r.rejected for r in burst)
    assert not {"position_step", "position_reacquired"} & {r.channel for r in records}
    assert max(e for t, e in errors if t <= STEP_AT + 3.0) < 3 * SIGMA


def test_a_burst_that_holds_its_offset_past_the_minimum_is_followed_and_left_at_once_when_it_ends():
    """12 fixes (1.2 s) at one 7 m offset, then back: indistinguishable from a step until it ends, so it is
    taken at its 6th fix. When it ends the fixes return to the level the step left, a known level (no
    offset to estimate, no cap on the evidence): back within 2 fixes, not 6, and then within 3 sigma of
    the truth again."""
    w = _car()
    samples = _edited(simulate(w), [(7.0, 0.0)] * 12)
    _, records, errors, heading_lost = _run(w, samples, _config())
    taken = [i for i, r in enumerate(records) if r.channel == "position_step"]
    assert len(taken) == 2 and taken[0] == 5
    assert 12 <= taken[1] <= 13  # the 1st or 2nd fix after the burst
    assert not heading_lost
    back = records[taken[1]].stamp
    assert max(e for t, e in errors if t >= back + 0.05) < 3 * SIGMA


def _scattered(samples: list, share: float, seed: int) -> tuple[list, int]:
    """From STEP_AT on, each fix an outlier with probability ``share``: 3-30 m in a uniform direction."""
    rng = np.random.default_rng(seed)
    out, n = [], 0
    for s in samples:
        if isinstance(s, GpsSample) and s.stamp >= STEP_AT - 1e-9 and rng.random() < share:
            r, a = rng.uniform(3.0, 30.0), rng.uniform(0.0, 2.0 * math.pi)
            s = _moved(s, r * math.cos(a), r * math.sin(a))
            n += 1
        out.append(s)
    return out, n


@pytest.mark.parametrize("alpha", [1e-3, 0.05])
def test_scattered_outliers_take_no_more_steps_than_the_stated_rate(alpha):
    """Half the fixes of 4 minutes are outliers in random directions (runs of 3-10 consecutive outliers
    happen dozens of times): no common offset, no step. Each run of gated-out fixes that follows an
    accepted one starts a test, and the stated bound is alpha per test: the steps taken stay within it
    (Poisson, 3 sigma above the mean it allows). At alpha = 0.05 the minimum run is 3 fixes, so the
    agreement of the innovations, not the run length, is what holds the outliers off."""
    w = _car(duration=300.0)
    samples, n = _scattered(simulate(w), 0.5, seed=4)
    _, records, _, _ = _run(w, samples, _config(f"step_false_alarm = {alpha}"))
    rejected = [r.rejected for r in records if r.channel in ("position", "position_step")]
    runs = sum(1 for a, b in zip(rejected, rejected[1:]) if b and not a)
    long_runs = sum(1 for i in range(len(rejected) - 3) if not rejected[i] and all(rejected[i + 1:i + 4]))
    steps = sum(r.channel == "position_step" for r in records)
    assert n > 1000 and runs > 300 and long_runs > 30  # the world is what it says
    allowed = alpha * runs
    assert steps <= allowed + 3.0 * math.sqrt(allowed), (steps, runs)


def test_white_noise_behind_a_tight_gate_takes_no_step_beyond_the_rate():
    """No outliers: 0.5 m white noise, but a gate at sqrt(NIS) 2 rejects ~13 % of ordinary fixes (runs of
    2-4 happen). Their innovations scatter about the filter's position, not about a new level: the steps
    taken stay within alpha per run (3 sigma, as above)."""
    w = _car(duration=300.0)
    _, records, _, _ = _run(w, simulate(w), _config("mahalanobis_threshold = 2.0"))
    rejected = [r.rejected for r in records if r.channel in ("position", "position_step")]
    runs = sum(1 for a, b in zip(rejected, rejected[1:]) if b and not a)
    steps = sum(r.channel == "position_step" for r in records)
    assert runs > 100
    allowed = 1e-3 * runs
    assert steps <= allowed + 3.0 * math.sqrt(allowed), (steps, runs)
