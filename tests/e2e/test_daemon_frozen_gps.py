"""A receiver that freezes (repeats its last fix with new stamps) reads as not alive in the daemon's health:
its repeats are applied (rejected as ``position_frozen``) but measure nothing (``Step.measured``), so they are
no sign of the receiver's life. Played over a real loopback Zenoh session at the recorded pace: a car at 10 m/s,
10 Hz fixes, frozen for the last 3 s (its GPS timeout 0.5 s)."""

from __future__ import annotations

import time

import zenoh

from fusiond.core.sensors import GpsSample, ImuSample, OdomSample, encode_sample
from fusiond.transport.daemon import Daemon

from tests.support.configs import loopback_daemon_config
from tests.support.loopback import sessions, wait_answering  # noqa: F401  (fixture)
from tests.support.sim_gps import T0, World, simulate

KEYS = {OdomSample: "t/odom", ImuSample: "t/imu", GpsSample: "t/gps"}
FREEZE_S = 3.0


def test_a_frozen_receiver_is_not_alive_while_its_repeats_keep_coming(sessions):  # noqa: F811
    dsession, client = sessions
    world = World(duration=9.0, odom_rate=50.0, imu_rate=100.0, gps_rate=10.0, speed=10.0,
                  datum=(48.137, 11.575, 520.0), gps_freeze=((9.0 - FREEZE_S, 9.0),))
    samples = simulate(world)
    cfg = loopback_daemon_config(imu="angular_velocity = true", extra='[[sensors]]\nname = "gps"\nkind = "gps"\n'
                                 'key = "t/gps"\ntimeout_s = 0.5\ndatum = [48.137, 11.575, 520.0]\n')
    daemon = Daemon(cfg, dsession, monitor=False)
    daemon.start()
    try:
        pubs = {k: client.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                for k, key in KEYS.items()}
        wait_answering(client)
        t0, s0 = time.monotonic(), samples[0].stamp
        alive_frozen = []
        for s in samples:  # at the recorded pace: liveness is wall time
            delay = (s.stamp - s0) - (time.monotonic() - t0)
            if delay > 0:
                time.sleep(delay)
            pubs[type(s)].put(encode_sample(s, "ros2-cdr"))
            if s.stamp - T0 > 9.0 - FREEZE_S + 1.5:  # a second and a half into the freeze: beyond its timeout
                alive_frozen.append(daemon.report().sensors["gps"].alive)
        rep = daemon.report()
        assert rep.sensors["gps"].applied > 0 and rep.sensors["gps"].received >= 80
        assert alive_frozen and not any(alive_frozen[-20:]), alive_frozen[-20:]
        assert rep.status != "ok" and any("gps" in p for p in rep.problems), rep.problems
    finally:
        daemon.stop()
