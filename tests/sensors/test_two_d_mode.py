"""`[filter] two_d_mode = true`: z, roll and pitch held at exactly 0 (robot_localization's meaning).

The simulated robot drives on flat ground, but its sensors say otherwise: the IMU
reports a 0.1 rad roll and gyro x/y rates, the odometry a vertical speed. In two-D
mode none of that may reach the state or any output, while the planar track still
follows the robot.
"""

from __future__ import annotations

import math

import msgspec
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config
from tests.support.sim import SimConfig, simulate
from tests.support.core_samples import make_config


def _config(two_d: bool, orientation: str = "absolute"):
    return make_config(orientation, extra_filter=f"two_d_mode = {'true' if two_d else 'false'}")


def _lying_about_the_vertical(samples):
    """The IMU says the robot rolls 0.1 rad and the gyro turns about x/y; the wheels climb 0.2 m/s."""
    out = []
    for s in samples:
        if isinstance(s, ImuSample):
            r, p, y = rot.to_rpy(s.orientation)
            w = s.angular_velocity
            s = msgspec.structs.replace(s, orientation=rot.from_rpy(r + 0.1, p - 0.05, y),
                                        angular_velocity=(w[0] + 0.02, w[1] - 0.03, w[2]))
        elif isinstance(s, OdomSample):
            s = msgspec.structs.replace(s, linear=(s.linear[0], s.linear[1], 0.2))
        out.append(s)
    return out


@pytest.mark.parametrize("orientation", ["absolute", "roll_pitch"])
def test_two_d_mode_outputs_z_roll_pitch_exactly_zero(orientation):
    sim = SimConfig(duration=20.0, standstill=1.0)
    samples = _lying_about_the_vertical(simulate(sim))
    core = FusionCore(_config(True, orientation))
    published = 0
    for s in samples:
        step = core.ingest(s)
        if step.publish:
            published += 1
            est = core.estimate()
            roll, pitch, _ = rot.to_rpy(est.orientation)
            assert est.position[2] == 0.0 and roll == 0.0 and pitch == 0.0
            assert est.orientation[0] == 0.0 and est.orientation[1] == 0.0
            P = est.pose_covariance
            for i in (2, 3, 4):  # z, roll, pitch rows and columns of the 6x6: held, so known exactly
                assert all(P[6 * i + j] == 0.0 and P[6 * j + i] == 0.0 for j in range(6))
            assert est.linear[2] == 0.0 and est.angular[0] == 0.0 and est.angular[1] == 0.0
    assert published > 500
    # the planar track still follows the robot: 1 m/s for 19 s with gyro-driven heading;
    # wheel noise 0.01 m/s and gyro noise 0.002 rad/s keep the end within a few decimetres
    t_end, x, y, _ = sim.truth[-1]
    _, xs = core.pose()
    assert math.hypot(xs[0] - x, xs[1] - y) < 0.5
    # and the same data without two_d_mode does move z (the lie reaches the state): the
    # test's input really is non-planar
    core3 = FusionCore(_config(False, orientation))
    for s in samples:
        core3.ingest(s)
    assert abs(core3.pose()[1][2]) > 1.0


def test_two_d_mode_does_not_fuse_gps_altitude():
    """A GPS whose altitude wanders: in two-D mode its fixes are fused as east/north only."""
    from tests.support.sim_gps import World, simulate as simulate_gps, truth_at

    world = World(duration=60.0, gps_rate=5.0, gps_sigma=0.3, datum=(48.137, 11.575, 520.0))
    samples = simulate_gps(world)
    samples = [msgspec.structs.replace(s, altitude=s.altitude + 0.2 * (s.stamp - 1000.0))
               if hasattr(s, "altitude") else s for s in samples]  # 12 m of altitude drift
    cfg = robot_config(gps="datum = [48.137, 11.575, 500.0]", filt="two_d_mode = true")
    core = FusionCore(cfg)
    dofs = set()
    for s in samples:
        step = core.ingest(s)
        dofs.update(r.dof for r in step.records if r.sensor == "gps")
        if step.publish:
            assert core.estimate().position[2] == 0.0  # the datum is 20 m below the fixes, and they climb
    assert dofs == {2}
    x, y, _ = truth_at(world, core.time)
    _, xs = core.pose()
    assert math.hypot(xs[0] - x, xs[1] - y) < 1.5  # 0.3 m fixes at 5 Hz, heading found from travel
