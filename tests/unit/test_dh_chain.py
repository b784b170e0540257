"""DH chains (modified and standard) and the tables of docs/robot-models.md §3-4."""
import math

import numpy as np
import pytest

from controllers.dh_chain import MODIFIED, STANDARD, DHChain, DHRow
from controllers.youbot_arm import (
    DATASHEET_LIMITS_DEG,
    datasheet_from_theta,
    theta_from_datasheet,
    youbot_arm_chain,
)
from controllers.zu12_arm import zu12_chain

DEG = math.pi / 180


def test_youbot_zero_pose_points_forward_with_the_wrist_up():
    tool = youbot_arm_chain().fk(np.zeros(5))
    assert tool[:3, 3] == pytest.approx([0.323, 0.0, 0.260], abs=1e-12)
    assert tool[:3, :3] == pytest.approx(np.eye(3), abs=1e-12)


def test_youbot_candle_pose():
    theta = theta_from_datasheet(np.zeros(5))
    assert theta == pytest.approx(np.radians([0, 90, 0, -90, 0]))
    assert youbot_arm_chain().fk(theta)[:3, 3] == pytest.approx([0.033, 0.0, 0.550], abs=1e-12)


def test_youbot_axes_are_vertical_then_three_parallel():
    frames = youbot_arm_chain().frames(np.radians([20, 40, -30, -60, 10]))
    z = [f[:3, 2] for f in frames[:5]]
    assert z[0] == pytest.approx([0, 0, 1], abs=1e-12)           # axis 1 vertical
    for i in (1, 2):
        assert abs(np.dot(z[i], z[3])) == pytest.approx(1.0)     # 2 parallel 3 parallel 4
    assert abs(np.dot(z[1], z[0])) == pytest.approx(0.0, abs=1e-12)


def test_youbot_limits_convert_from_the_datasheet():
    lower, upper = youbot_arm_chain().limits
    assert np.degrees(lower) == pytest.approx([-169, 0, -146, -192, -167])
    assert np.degrees(upper) == pytest.approx([169, 155, 151, 12, 167])
    rng = np.random.default_rng(5)
    lo, hi = np.radians(np.array(DATASHEET_LIMITS_DEG)).T
    for _ in range(100):
        phi = rng.uniform(lo, hi)
        theta = theta_from_datasheet(phi)
        assert youbot_arm_chain().within_limits(theta)
        assert datasheet_from_theta(theta) == pytest.approx(phi)


def test_zu12_flange_at_zero():
    tool = zu12_chain().fk(np.zeros(6))
    assert tool[:3, 3] == pytest.approx([1.1665, 0.028, 0.02765], abs=1e-12)
    assert tool[:3, :3] == pytest.approx(np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), abs=1e-12)


def _rotation(axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


@pytest.mark.parametrize('chain', [youbot_arm_chain(), zu12_chain()], ids=['mdh', 'dh'])
def test_each_joint_rotates_the_tool_about_its_own_axis(chain):
    """Independent of how the formulas are written: turning joint i by delta rotates the tool
    about joint i's axis, the z axis of frame i (modified) or of frame i-1 (standard)."""
    rng = np.random.default_rng(6)
    lower, upper = chain.limits
    for _ in range(50):
        q = rng.uniform(lower, upper)
        frames = [np.eye(4)] + chain.frames(q)[:-1]
        tool = chain.fk(q)
        for i in range(chain.dof):
            axis_frame = frames[i + 1] if chain.convention == MODIFIED else frames[i]
            origin, axis = axis_frame[:3, 3], axis_frame[:3, 2]
            delta = 0.3
            moved = chain.fk(q + delta * np.eye(chain.dof)[i])
            r = _rotation(axis, delta)
            assert moved[:3, 3] == pytest.approx(origin + r @ (tool[:3, 3] - origin), abs=1e-12)
            assert moved[:3, :3] == pytest.approx(r @ tool[:3, :3], abs=1e-12)


def test_conventions_agree_on_a_planar_arm():
    # A planar 2R arm: standard rows (a1, a2) equal modified rows (0, a1) plus a tool offset a2.
    std = DHChain((DHRow(0, 0.4, 0), DHRow(0, 0.3, 0)), STANDARD)
    tool = np.eye(4)
    tool[0, 3] = 0.3
    mod = DHChain((DHRow(0, 0, 0), DHRow(0, 0.4, 0)), MODIFIED, tuple(map(tuple, tool)))
    for q in np.random.default_rng(7).uniform(-3, 3, size=(50, 2)):
        assert std.fk(q) == pytest.approx(mod.fk(q), abs=1e-12)
        x = 0.4 * math.cos(q[0]) + 0.3 * math.cos(q[0] + q[1])
        assert std.fk(q)[0, 3] == pytest.approx(x)


def test_bad_input_raises():
    chain = youbot_arm_chain()
    with pytest.raises(ValueError, match='expected 5'):
        chain.fk(np.zeros(4))
    with pytest.raises(ValueError, match='finite'):
        chain.fk([0, 0, math.nan, 0, 0])
    with pytest.raises(ValueError):
        DHRow(0, 0, 0, lower=1.0, upper=-1.0)
    with pytest.raises(ValueError):
        DHChain((), MODIFIED)
    with pytest.raises(ValueError):
        DHChain((DHRow(0, 0, 0),), 'craig')


@pytest.mark.parametrize('convention', [MODIFIED, STANDARD])
def test_the_float_fk_is_the_product_of_the_joint_transforms(convention):
    """fk multiplies each joint's transform out in floats: the same pose as the 4x4 matrix
    products of ``frames``, with offsets, twists and a tool."""
    rng = np.random.default_rng(7)
    rows = tuple(DHRow(alpha, a, d, offset) for alpha, a, d, offset in
                 rng.uniform(-1.5, 1.5, (6, 4)))
    tool = np.eye(4)
    tool[:3, 3] = (0.01, -0.02, 0.1)
    tool[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for chain in (DHChain(rows, convention), DHChain(rows, convention, tuple(map(tuple, tool)))):
        for _ in range(50):
            q = rng.uniform(-math.pi, math.pi, 6)
            np.testing.assert_allclose(chain.fk(q), chain.frames(q)[-1], atol=1e-14)
            np.testing.assert_allclose(chain.fk(list(q)), chain.fk(tuple(q)), atol=0.0)
    with pytest.raises(ValueError, match='expected 6'):
        chain.fk(np.zeros((2, 3)))
    with pytest.raises(ValueError, match='expected 6'):
        chain.fk(None)
    with pytest.raises(ValueError, match='finite'):
        chain.fk([0.0, 0.0, 0.0, math.inf, 0.0, 0.0])
