"""A drive that reads exactly zero for seconds while the vehicle drives on (a dropout under way), on a straight road.

The gyro is then as quiet as at rest, so the zero runs look like standstills by the gyro alone. But the drive
dropped to zero from 18 m/s within one odometry period, which no vehicle does (the core's ``impossible_stop``:
beyond 15 m/s^2), and the core coasts on at ``coast_decel`` (0.5 m/s^2: 36 s from 18 m/s, longer than any of
the 3 s dropouts). The doctor must read them as the core does: not standstills (no gyro bias "at rest" from
them), and no chord of the wheel-scale check across them (the wheels' travel stopped, the vehicle's did not).
A genuine stop from 1 m/s (a drop a vehicle can make) stays a standstill.
"""

from __future__ import annotations

import pytest

from fusiond.doctor.gyro import coasts, quiet_episodes
from fusiond.replay.run import run_samples

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig, simulate

DROPOUTS = ((8.0, 11.0), (18.0, 21.0), (28.0, 31.0))


def _series(**kw):
    cfg = make_config()
    result = run_samples(simulate(SimConfig(**{"duration": 40.0, "turn_amplitude": 0.0, **kw})), cfg)
    return result.doctor.series(), cfg


def test_dropouts_at_speed_are_coasts_not_standstills():
    series, cfg = _series(speed=18.0, standstill=3.0, dropouts=DROPOUTS, gyro_bias=(0.0, 0.0, 0.004))
    rest, _ = quiet_episodes(series, cfg, cfg.sensors[1])
    assert len(rest) == 1 and rest[0].t0 < 1003.0, rest  # the standstill before driving, nothing after
    spans = coasts(series, cfg)
    assert len(spans) == 3, spans
    for (a, b), (d0, d1) in zip(spans, DROPOUTS):  # each dropout, its bins wholly at zero (0.1 s bins at 50 Hz)
        assert a == pytest.approx(1000.0 + d0, abs=0.3) and b == pytest.approx(1000.0 + d1, abs=0.3)


def test_a_stop_a_vehicle_can_make_stays_a_standstill():
    series, cfg = _series(speed=1.0, standstill=3.0, stops=((15.0, 20.0),))
    rest, _ = quiet_episodes(series, cfg, cfg.sensors[1])
    assert len(rest) == 2, rest
    assert coasts(series, cfg) == []


def test_a_rest_span_that_begins_in_a_turn_keeps_its_quiet_stretch():
    """A drive at 5 Hz reads zero from 10 s to 18 s while the robot still turns (0.2 rad/s) until 12 s, then
    stands: the filter's rest test, on so few messages, takes the span whole. Averaged whole its gyro turns (no
    standstill at all); split at its turning bins, the 6 s it stood are a standstill with the gyro's own noise
    (0.002 rad/s), and the turn is not. (At 50 Hz the filter's span begins at 11.7 s: nothing to split.)"""
    series, cfg = _series(speed=1.0, turn_amplitude=0.0, standstill=3.0, false_stops=((10.0, 12.0, 0.2),),
                          stops=((12.0, 18.0),), odom_rate=5.0)
    assert any(a < 1010.5 < b for a, b in series.rest_spans), series.rest_spans  # the trait
    rest, turning = quiet_episodes(series, cfg, cfg.sensors[1])
    late = [e for e in rest if e.t0 > 1009.0]
    assert len(late) == 1 and late[0].t0 >= 1011.5 and late[0].t1 == pytest.approx(1018.0, abs=0.6), late
    assert late[0].gyro_sigma < 0.004, late[0]
    assert any(e.t0 < 1011.0 for e in turning), turning


def test_a_push_with_the_wheels_at_zero_leaves_no_standstill_between_its_turns():
    """Pushed by hand from 10 s to 19 s: the wheels read zero while the robot rolls at 1 m/s, straight but for a
    short turn every second (0.3 s at 0.3 rad/s, the last one ending the push). Between the turns its gyro is as
    quiet as at rest: taken as standstills, those pieces gave the noise and the bias "at rest" of a moving
    vehicle. A parked vehicle does not start to turn with its wheels at zero: no piece before a turn is a
    standstill; the genuine stop after the push (25-30 s) is."""
    turns = tuple((10.0 + k, 10.3 + k, 0.3 if k % 2 else -0.3) for k in range(8)) + ((18.7, 19.0, 0.3),)
    series, cfg = _series(speed=1.0, standstill=3.0, dropouts=((10.0, 19.0),), false_stops=turns,
                          stops=((25.0, 30.0),))
    rest, turning = quiet_episodes(series, cfg, cfg.sensors[1])
    assert not [e for e in rest if e.t1 > 1010.0 and e.t0 < 1019.0], rest
    assert [e for e in rest if e.t0 >= 1024.9 and e.t1 == pytest.approx(1030.0, abs=0.3)], rest
    assert any(e.t0 < 1019.0 and e.t1 > 1018.0 for e in turning), turning  # the push: a zero run that turned
