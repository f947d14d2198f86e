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
