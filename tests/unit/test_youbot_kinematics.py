"""youBot kinematics in the description's convention (the kinematics node's core)."""
import math

import numpy as np
import pytest

from controllers.arm_model import motion_duration
from controllers.transforms import (
    matrix_to_quaternion,
    pose_matrix,
    quaternion_to_matrix,
    rotation_angle,
)
from controllers.youbot_kinematics import YoubotKinematics, in_base_link


def _random_rotation(rng):
    q = rng.normal(size=4)
    return quaternion_to_matrix(q / np.linalg.norm(q))


def test_quaternion_round_trips():
    rng = np.random.default_rng(1)
    for _ in range(500):
        r = _random_rotation(rng)
        assert quaternion_to_matrix(matrix_to_quaternion(r)) == pytest.approx(r, abs=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
    assert rotation_angle(quaternion_to_matrix((0, 0, math.sin(0.3), math.cos(0.3)))) == \
        pytest.approx(0.6)
    with pytest.raises(ValueError):
        quaternion_to_matrix((0, 0, 0, 0))


@pytest.mark.parametrize('tool', ['gripper_tcp', 'arm_link_5'])
def test_fk_ik_fk_round_trips_in_the_description_convention(tool):
    kin = YoubotKinematics(tool)
    rng = np.random.default_rng(7)
    solved = 0
    for _ in range(300):
        q = rng.uniform(kin.lower, kin.upper)
        target = kin.fk(q)
        result = kin.ik(target, seed=rng.uniform(kin.lower, kin.upper))
        if result.success:
            solved += 1
            assert kin.within_limits(result.positions)
            assert result.position_error < 1e-7 and result.rotation_error < 1e-7
            assert kin.fk(result.positions) == pytest.approx(target, abs=1e-7)
    assert solved / 300 >= 0.995


def test_the_seed_picks_the_nearest_solution():
    kin = YoubotKinematics()
    q = np.array([0.3, 0.5, -0.9, 0.6, 0.2])
    result = kin.ik(kin.fk(q), seed=q + 0.01)
    assert result.positions == pytest.approx(q, abs=1e-9)


def test_unreachable_targets_fail_with_a_reason():
    kin = YoubotKinematics()
    far = pose_matrix((1.5, 0.0, 0.3), (0, 0, 0, 1))
    result = kin.ik(far)
    assert not result.success and 'out of reach' in result.reason and result.positions is None
    # Approach (tool z) pointing sideways, out of the arm's plane through the target.
    sideways = np.eye(4)
    sideways[:3, :3] = quaternion_to_matrix((math.sin(-math.pi / 4), 0, 0, math.cos(math.pi / 4)))
    sideways[:3, 3] = (0.45, 0.0, 0.2)
    result = kin.ik(sideways)
    assert not result.success and 'not in the arm plane' in result.reason
    assert not kin.ik(np.full((4, 4), np.nan)).success


def test_reference_frames_and_tools():
    pose = pose_matrix((0.1, 0.0, 0.2), (0, 0, 0, 1))
    assert in_base_link('', pose)[:3, 3] == pytest.approx((0.1, 0.0, 0.2))
    assert in_base_link('yb/base_link', pose, 'yb/')[:3, 3] == pytest.approx((0.1, 0.0, 0.2))
    assert in_base_link('arm_base_frame', pose)[:3, 3] == pytest.approx((0.267, 0.0, 0.214))
    with pytest.raises(KeyError, match='unknown frame "odom"'):
        in_base_link('odom', pose)
    with pytest.raises(ValueError, match='unknown tool frame'):
        YoubotKinematics('wrist')
    # Candle pose: the gripper's grasp point straight above the arm base.
    tcp = YoubotKinematics().fk(np.zeros(5))
    assert tcp[:3, 3] == pytest.approx((0.167 + 0.033, 0.0, 0.014 + 0.550 + 0.1046))


def test_motion_duration_keeps_peak_speed_within_the_scaled_limit():
    limits = np.full(5, math.pi / 2)
    assert motion_duration(np.zeros(5), [0, 1.0, 0, 0, 0], limits, 0.5) == \
        pytest.approx(1.5 / (math.pi / 4))
    assert motion_duration(np.zeros(5), np.zeros(5), limits, 1.0, min_duration=0.5) == 0.5
    with pytest.raises(ValueError):
        motion_duration(np.zeros(5), np.zeros(5), limits, 0.0)
