"""youBot Mecanum kinematics against ROBOT_MODELS.md §2 (the paper's eq. 9)."""
import numpy as np
import pytest

from controllers.mecanum import (MecanumGeometry, body_twist, paper_to_forward_positive,
                                 paper_wheel_speeds, wheel_speeds)

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
