"""Kinematics of the mini robot against docs/robot-models.md §1."""
import math

import pytest

from controllers.diff_drive import (
    DiffDriveGeometry,
    Pose2D,
    body_twist,
    integrate_unicycle,
    predict_pose,
    wheel_speeds,
    wrap_angle,
)

# (v, w) -> (wL, wR), the table of docs/robot-models.md §1.
TABLE = [
    ((0.2, 0.0), (6.666667, 6.666667)),
    ((0.0, 0.2), (-0.376667, 0.376667)),
    ((0.2, 0.2), (6.290000, 7.043333)),
    ((0.1, -0.2), (3.710000, 2.956667)),
]


@pytest.mark.parametrize('twist, wheels', TABLE)
def test_wheel_speeds_match_the_report_table(twist, wheels):
    left, right = wheel_speeds(*twist)
    assert left == pytest.approx(wheels[0], abs=1e-6)
    assert right == pytest.approx(wheels[1], abs=1e-6)


@pytest.mark.parametrize('twist, wheels', TABLE)
def test_inverse_recovers_the_twist(twist, wheels):
    v, w = body_twist(*wheels)
    assert v == pytest.approx(twist[0], abs=1e-5)
    assert w == pytest.approx(twist[1], abs=1e-5)


def test_round_trip_for_random_twists():
    import random
    rng = random.Random(7)
    geom = DiffDriveGeometry(0.05, 0.3)
    for _ in range(1000):
        v, w = rng.uniform(-1, 1), rng.uniform(-3, 3)
        assert body_twist(*wheel_speeds(v, w, geom), geom) == pytest.approx((v, w), abs=1e-12)


def test_report_buttons_give_half_max_speed_per_wheel():
    # The report's forward button: both wheels at 0.5 * max_speed / r.
    left, right = wheel_speeds(0.5 * 0.2, 0.0)
    assert left == right == pytest.approx(0.5 * 0.2 / 0.03)


def test_geometry_rejects_non_positive_values():
    with pytest.raises(ValueError):
        DiffDriveGeometry(0.0, 0.1)
    with pytest.raises(ValueError):
        DiffDriveGeometry(0.03, float('nan'))


def test_straight_line_and_turn_in_place():
    p = integrate_unicycle(Pose2D(), 0.1, 0.0, 2.0)
    assert (p.x, p.y, p.yaw) == pytest.approx((0.2, 0.0, 0.0))
    p = integrate_unicycle(Pose2D(), 0.0, 0.2, math.pi / 0.2 / 2)
    assert (p.x, p.y, p.yaw) == pytest.approx((0.0, 0.0, math.pi / 2))


def test_arc_matches_fine_euler_integration():
    exact = integrate_unicycle(Pose2D(0.1, -0.2, 0.3), 0.2, 0.5, 3.0)
    x, y, yaw, dt = 0.1, -0.2, 0.3, 1e-5
    for _ in range(300000):
        x += 0.2 * math.cos(yaw) * dt
        y += 0.2 * math.sin(yaw) * dt
        yaw += 0.5 * dt
    assert (exact.x, exact.y) == pytest.approx((x, y), abs=1e-5)
    assert exact.yaw == pytest.approx(wrap_angle(yaw), abs=1e-9)


def test_a_square_closes():
    leg, turn = (0.1, 0.0, 5.0), (0.0, 0.2, math.pi / 2 / 0.2)
    end = predict_pose(Pose2D(), [leg, turn] * 4)
    assert (end.x, end.y) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert wrap_angle(end.yaw) == pytest.approx(0.0, abs=1e-12)


def test_wrap_angle_range():
    for a in (-10.0, -math.pi, 0.0, math.pi, 7.5):
        wrapped = wrap_angle(a)
        assert -math.pi <= wrapped < math.pi
        assert math.cos(wrapped) == pytest.approx(math.cos(a))

