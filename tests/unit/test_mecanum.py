"""youBot Mecanum kinematics against docs/robot-models.md §2 (the paper's eq. 9)."""
import math

import numpy as np
import pytest

from controllers.mecanum import (
    MecanumGeometry,
    body_twist,
    paper_to_forward_positive,
    paper_wheel_speeds,
    wheel_speeds,
)

GEOM = MecanumGeometry(0.0475, 0.385)   # the values of the worked table

TABLE = [  # (vx, vy, wz) -> paper w1..w4, forward-positive FL, FR, RR, RL
    ((0.2, 0.0, 0.0), (4.21053, -4.21053, -4.21053, 4.21053), (4.21053,) * 4),
    ((0.0, 0.2, 0.0), (-4.21053, -4.21053, 4.21053, 4.21053),
     (-4.21053, 4.21053, -4.21053, 4.21053)),
]


@pytest.mark.parametrize('twist, paper, forward', TABLE)
def test_the_worked_table(twist, paper, forward):
    assert paper_wheel_speeds(*twist, GEOM) == pytest.approx(paper, abs=1e-5)
    assert wheel_speeds(*twist, GEOM) == pytest.approx(forward, abs=1e-5)


def test_eq9_converted_is_the_forward_positive_inverse_kinematics():
    rng = np.random.default_rng(3)
    for vx, vy, wz in rng.uniform(-1, 1, size=(200, 3)):
        assert paper_to_forward_positive(paper_wheel_speeds(vx, vy, wz, GEOM)) == \
            pytest.approx(wheel_speeds(vx, vy, wz, GEOM), abs=1e-12)


def test_forward_kinematics_inverts_the_inverse():
    rng = np.random.default_rng(4)
    for twist in rng.uniform(-1, 1, size=(200, 3)):
        assert body_twist(wheel_speeds(*twist, GEOM), GEOM) == pytest.approx(tuple(twist),
                                                                             abs=1e-12)


def test_pure_rotation_turns_the_sides_against_each_other():
    fl, fr, rr, rl = wheel_speeds(0.0, 0.0, 1.0, GEOM)
    assert fl == rl < 0 < fr == rr
    assert fr == pytest.approx(0.385 / 0.0475)


def test_geometry_is_validated():
    with pytest.raises(ValueError):
        MecanumGeometry(0.0, 0.385)
    with pytest.raises(ValueError):
        MecanumGeometry(0.0475, float('inf'))


def test_integrate_twist_matches_small_steps():
    from controllers.base_fidelity import integrate_twist
    from controllers.diff_drive import Pose2D
    exact = integrate_twist(Pose2D(0.3, -0.2, 0.4), 0.15, -0.1, 0.3, 2.0)
    pose = Pose2D(0.3, -0.2, 0.4)
    for _ in range(20000):
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        pose = Pose2D(pose.x + (0.15 * c + 0.1 * s) * 1e-4, pose.y + (0.15 * s - 0.1 * c) * 1e-4,
                      pose.yaw + 0.3e-4)
    assert (exact.x, exact.y, exact.yaw) == pytest.approx((pose.x, pose.y, pose.yaw), abs=1e-5)


def test_tracking_errors_separate_along_and_across():
    from controllers.base_fidelity import tracking_errors
    from controllers.diff_drive import Pose2D
    # 2 % short and 1 % to the side of a 0.4 m straight line.
    e = tracking_errors((0.2, 0.0, 0.0), 2.0, Pose2D(), Pose2D(0.392, 0.004, 0.0),
                        (0.198, 0.0, 0.0), 0.386)
    assert e.path_length == pytest.approx(0.4)
    assert e.cross_drift == pytest.approx(0.01)
    assert e.position_error == pytest.approx(math.hypot(0.008, 0.004) / 0.4)
    assert e.twist_error == pytest.approx(0.01)
    # Turning in place: translation is drift, relative to the wheels' travel.
    e = tracking_errors((0.0, 0.0, 0.5), 2.0, Pose2D(), Pose2D(0.00386, 0.0, 0.99),
                        (0.0, 0.0, 0.5), 0.386)
    assert e.cross_drift == pytest.approx(0.01)
    assert e.yaw_error == pytest.approx(0.01)
    with pytest.raises(ValueError):
        tracking_errors((0.0, 0.0, 0.0), 1.0, Pose2D(), Pose2D(), (0.0, 0.0, 0.0), 0.386)
