"""Analytic IK of the youBot arm, measured as the issue asks: 1000 targets made by FK."""
import math

import numpy as np
import pytest

from controllers.youbot_arm import youbot_arm_chain
from controllers.youbot_ik import solve_ik

CHAIN = youbot_arm_chain()


def test_fk_generated_targets_are_solved_exactly_within_limits():
    rng = np.random.default_rng(11)
    lower, upper = CHAIN.limits
    solved, errors = 0, []
    for _ in range(1000):
        q = rng.uniform(lower, upper)
        target = CHAIN.fk(q)
        result = solve_ik(target, q_seed=np.zeros(5))
        if result.success:
            solved += 1
            assert CHAIN.within_limits(result.q)
            reached = CHAIN.fk(result.q)
            errors.append(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
            assert reached[:3, :3] == pytest.approx(target[:3, :3], abs=1e-6)
    assert solved / 1000 >= 0.995
    assert max(errors) < 1e-4   # 0.1 mm


def test_the_seed_selects_among_solutions():
    q = np.radians([30.0, 60.0, -40.0, -80.0, 20.0])
    result = solve_ik(CHAIN.fk(q), q_seed=q)
    assert result.success and result.q == pytest.approx(q, abs=1e-9)
    assert len(result.candidates) >= 2   # elbow up and down at least


def test_unreachable_targets_fail_clearly():
    far = np.eye(4)
    far[:3, 3] = [1.0, 0.0, 0.3]
    result = solve_ik(far)
    assert not result.success and 'out of reach' in result.reason
    tilted = CHAIN.fk(np.radians([0, 60, -30, -40, 0]))
    # Turn the approach out of the arm's plane: no 5-joint configuration has it.
    c, s = math.cos(0.3), math.sin(0.3)
    tilted[:3, :3] = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ tilted[:3, :3]
    result = solve_ik(tilted)
    assert not result.success and 'plane' in result.reason
    assert not solve_ik(np.full((4, 4), np.nan)).success
