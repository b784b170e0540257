"""youBot arm kinematics in the robot description's terms: joint positions as the description
(and /joint_states) gives them, poses of a tool frame in base_link or the arm's base frame.
Wraps the MDH chain (controllers.youbot_arm) and the analytic IK (controllers.youbot_ik)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence

import numpy as np

from controllers.transforms import rotation_angle, translation
from controllers.youbot_arm import (ARM_BASE_IN_BASE_LINK_M, GRIPPER_TCP_OFFSET_M, JOINT_NAMES,
                                    JOINT_VELOCITY_LIMIT, datasheet_from_theta,
                                    theta_from_datasheet, youbot_arm_chain)
from controllers.youbot_ik import solve_ik

# Tool frames of the description, as transforms from the joint-5 flange (arm_link_5).
TOOL_FRAMES: Dict[str, np.ndarray] = {
    'arm_link_5': np.eye(4),
    'gripper_palm_link': np.eye(4),
    'gripper_tcp': translation(z=GRIPPER_TCP_OFFSET_M),
}
# Frames a target may be given in, as transforms from base_link.
REFERENCE_FRAMES: Dict[str, np.ndarray] = {
    'base_link': np.eye(4),
    'arm_base_frame': translation(*ARM_BASE_IN_BASE_LINK_M),
}


@dataclass
class ArmSolution:
    success: bool
    positions: Optional[np.ndarray] = None     # description convention, JOINT_NAMES order
    reason: str = ''
    position_error: float = math.inf
    rotation_error: float = math.inf


class YoubotKinematics:
    """FK and IK of the youBot arm for one tool frame."""

    joint_names = JOINT_NAMES

    def __init__(self, tool_frame: str = 'gripper_tcp') -> None:
        if tool_frame not in TOOL_FRAMES:
            raise ValueError(f'unknown tool frame "{tool_frame}"; known: {sorted(TOOL_FRAMES)}')
        self.tool_frame = tool_frame
        self.chain = youbot_arm_chain()
        self._tool = TOOL_FRAMES[tool_frame]
        self._tool_inv = np.linalg.inv(self._tool)
        self._base = REFERENCE_FRAMES['arm_base_frame']
        self._base_inv = np.linalg.inv(self._base)
        lower, upper = self.chain.limits
        ends = np.sort(np.stack([datasheet_from_theta(lower), datasheet_from_theta(upper)]), 0)
        self.lower, self.upper = ends[0], ends[1]
        self.velocity_limits = np.full(5, JOINT_VELOCITY_LIMIT)

    def fk(self, positions: Sequence[float]) -> np.ndarray:
        """4x4 pose of the tool frame in base_link."""
        theta = theta_from_datasheet(positions)
        return self._base @ self.chain.fk(theta) @ self._tool

    def ik(self, target: np.ndarray, seed: Optional[Sequence[float]] = None) -> ArmSolution:
        """Joint positions that put the tool frame at ``target`` (4x4 in base_link), nearest
        to ``seed``; a failure names why (out of reach, orientation, limits)."""
        target = np.asarray(target, float)
        if target.shape != (4, 4) or not np.all(np.isfinite(target)):
            return ArmSolution(False, reason='target must be a finite 4x4 pose')
        flange = self._base_inv @ target @ self._tool_inv
        seed_theta = None if seed is None else theta_from_datasheet(seed)
        result = solve_ik(flange, seed_theta, self.chain)
        if not result.success:
            return ArmSolution(False, reason=result.reason)
        positions = datasheet_from_theta(result.q)
        reached = self.fk(positions)
        return ArmSolution(True, positions, '',
                           float(np.linalg.norm(reached[:3, 3] - target[:3, 3])),
                           rotation_angle(reached[:3, :3].T @ target[:3, :3]))

    def within_limits(self, positions: Sequence[float], tol: float = 1e-9) -> bool:
        q = np.asarray(positions, float)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))


def in_base_link(frame: str, pose: np.ndarray, prefix: str = '') -> np.ndarray:
    """A pose given in ``frame`` (base_link or arm_base_frame, with the robot's frame prefix;
    empty means base_link) as a pose in base_link. Raises KeyError for other frames."""
    name = frame[len(prefix):] if prefix and frame.startswith(prefix) else frame
    name = name or 'base_link'
    if name not in REFERENCE_FRAMES:
        raise KeyError(f'unknown frame "{frame}": targets must be given in '
                       f'{[prefix + f for f in REFERENCE_FRAMES]} (no tf2 lookup here)')
    return REFERENCE_FRAMES[name] @ np.asarray(pose, float)


def motion_duration(start: Sequence[float], goal: Sequence[float],
                    velocity_limits: Sequence[float], scaling: float,
                    min_duration: float = 0.5) -> float:
    """Duration of a rest-to-rest cubic move whose peak joint speed (1.5x the average) stays
    within ``scaling`` times the velocity limits."""
    if not 0.0 < scaling <= 1.0:
        raise ValueError(f'velocity scaling must be within (0, 1], got {scaling}')
    step = np.abs(np.subtract(goal, start))
    return max(min_duration, float(np.max(1.5 * step / (np.asarray(velocity_limits) * scaling))))
