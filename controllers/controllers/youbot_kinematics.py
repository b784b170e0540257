"""The youBot arm's kinematics in the description's terms (see arm_model.py)."""
from __future__ import annotations

from typing import Dict

import numpy as np

from controllers.arm_model import ArmKinematics
from controllers.transforms import translation
from controllers.youbot_arm import (
    ARM_BASE_IN_BASE_LINK_M,
    GRIPPER_TCP_OFFSET_M,
    JOINT_NAMES,
    JOINT_VELOCITY_LIMIT,
    datasheet_from_theta,
    theta_from_datasheet,
    youbot_arm_chain,
)
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


class YoubotKinematics(ArmKinematics):
    """FK and IK of the youBot arm (datasheet joint angles) for one tool frame."""

    def __init__(self, tool_frame: str = 'gripper_tcp') -> None:
        super().__init__(youbot_arm_chain(), solve_ik, JOINT_NAMES,
                         np.full(5, JOINT_VELOCITY_LIMIT), REFERENCE_FRAMES['arm_base_frame'],
                         TOOL_FRAMES, tool_frame, REFERENCE_FRAMES, theta_from_datasheet,
                         datasheet_from_theta)


def in_base_link(frame: str, pose: np.ndarray, prefix: str = '') -> np.ndarray:
    """A pose in base_link or arm_base_frame (with the robot's prefix) as a pose in base_link."""
    return YoubotKinematics().in_base_link(frame, pose, prefix)
