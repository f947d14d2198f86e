"""The map -> odom -> base_link maths (core/tf_tree.py): the world correction composes back to the
world pose, and the odometry frame stays continuous while the world estimate jumps."""

from __future__ import annotations

import math
import random

import pytest

from fusiond.config import loads
from fusiond.core.tf_tree import OdomFrame, compose, inverse, map_to_odom, tf_tree_active
from fusiond.estimator import rotation as rot

from tests.support.configs import robot_config_text


def random_transform(rng: random.Random, tilt: float = 0.5):
    p = tuple(rng.uniform(-50.0, 50.0) for _ in range(3))
    q = rot.from_rpy(rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rng.uniform(-math.pi, math.pi))
    return p, q


def assert_same(a, b, tol=1e-9):
    (pa, qa), (pb, qb) = a, b
    assert max(abs(x - y) for x, y in zip(pa, pb)) < tol
    sign = 1.0 if sum(x * y for x, y in zip(qa, qb)) >= 0.0 else -1.0  # q and -q are one rotation
    assert max(abs(x - sign * y) for x, y in zip(qa, qb)) < tol


def test_map_to_odom_composed_with_odom_to_base_gives_map_to_base():
    rng = random.Random(7)
    for _ in range(500):
        map_base, odom_base = random_transform(rng), random_transform(rng)
        assert_same(compose(map_to_odom(map_base, odom_base), odom_base), map_base)


def test_inverse_undoes_a_transform_and_compose_matches_the_rotation_matrix():
    rng = random.Random(3)
    for _ in range(200):
        a, b = random_transform(rng, tilt=1.2), random_transform(rng, tilt=1.2)
        assert_same(compose(inverse(a), a), ((0.0, 0.0, 0.0), rot.IDENTITY))
        p, _ = compose(a, b)
        expected = rot.matrix(a[1]) @ b[0]
        assert max(abs(p[i] - (a[0][i] + expected[i])) for i in range(3)) < 1e-9


def test_the_odom_frame_integrates_the_twist_and_ignores_world_jumps():
    """Driving a circle at 1 m/s and 0.5 rad/s: the odometry frame follows the arc; a 3 m world jump
    (a GPS correction) and a turned world heading leave it continuous, map -> odom takes them, and
    map -> odom stays a translation and a turn about z (both frames share the vertical)."""
    frame = OdomFrame(max_step_s=0.2)
    dt, v, w = 0.02, 1.0, 0.5
    world_p, yaw = (0.0, 0.0, 0.0), 0.0
    tilt = rot.from_rpy(0.02, -0.01, 0.0)
    previous = None
    for k in range(300):
        t = 100.0 + k * dt
        jump = (3.0, -1.0, 0.0) if k >= 150 else (0.0, 0.0, 0.0)
        turn = 0.3 if k >= 150 else 0.0
        yaw_w = yaw + turn
        pw = (world_p[0] + jump[0], world_p[1] + jump[1], 0.0)
        qw = rot.mul(rot.from_rpy(0.0, 0.0, yaw_w), tilt)
        odom_p, odom_q = frame.advance(t, pw, qw, (v, 0.0, 0.0), (0.0, 0.0, w))
        if previous is not None:  # continuous: one step of travel, never the jump
            step = math.dist(odom_p, previous)
            assert step == pytest.approx(v * dt, rel=0.01)
        previous = odom_p
        m2o_p, m2o_q = map_to_odom((pw, qw), (odom_p, odom_q))
        roll, pitch, _ = rot.to_rpy(m2o_q)
        assert abs(roll) < 1e-9 and abs(pitch) < 1e-9
        assert_same(compose((m2o_p, m2o_q), (odom_p, odom_q)), (pw, qw))
        # the "world" of this test: the exact arc
        yaw += w * dt
        world_p = (math.sin(yaw) / w * v, (1.0 - math.cos(yaw)) / w * v, 0.0)
    # the odometry frame drove the same arc as the world before the jump (k = 299 integrated 299 steps)
    yaw_end = 299 * w * dt
    arc = (math.sin(yaw_end) / w * v, (1.0 - math.cos(yaw_end)) / w * v)
    assert math.dist(odom_p[:2], arc) < 1e-3
    # a body z rate under a tilt turns the heading a little slower (cos roll cos pitch ~ 1 - 2.5e-4)
    assert rot.wrap(rot.yaw(odom_q) - yaw_end) == pytest.approx(0.0, abs=1e-3)
    assert rot.to_rpy(odom_q)[0] == pytest.approx(0.02, abs=1e-9)  # roll and pitch are the estimate's


def test_a_stamp_that_does_not_advance_leaves_the_frame_and_a_gap_holds_the_twist_at_most_max_step():
    frame = OdomFrame(max_step_s=0.2)
    first = frame.advance(10.0, (1.0, 2.0, 0.0), rot.IDENTITY, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert first == ((1.0, 2.0, 0.0), rot.IDENTITY)  # the first estimate defines the frame
    assert frame.advance(9.5, (5.0, 5.0, 0.0), rot.IDENTITY, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == first
    p, _ = frame.advance(20.0, (30.0, 2.0, 0.0), rot.IDENTITY, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert p[0] == pytest.approx(1.2, abs=1e-12)  # 10 s of gap, 0.2 s of held twist


@pytest.mark.parametrize("gps, output, active", [
    ("", "", True),
    (None, "", False),  # no world sensor: odom -> base_link as before
    ("", 'map_frame = ""', False),
    ("", 'frame_id = "map"', False),  # the old way of naming a GPS world: one transform map -> base_link
    ("", "publish_tf = false", False),
])
def test_the_tree_is_published_only_with_a_world_sensor_and_a_distinct_map_frame(gps, output, active):
    cfg = loads(f"[output]\n{output}\n" + robot_config_text(gps=gps))
    assert tf_tree_active(cfg) is active
