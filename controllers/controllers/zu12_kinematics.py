"""The Zu 12's kinematics in the description's terms (see arm_model.py)."""
from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from controllers.arm_model import ArmKinematics
from controllers.transforms import translation
from controllers.zu12_arm import (
    JOINT_NAMES,
    JOINT_VELOCITY_LIMITS,
    SUCTION_TCP_OFFSET_M,
    zu12_chain,
)
from controllers.zu12_ik import solve_ik

# The base stands on the floor: every joint frame above the shoulder's housing height.
FLOOR_CLEARANCE_M = 0.08
TOOL_FRAMES: Dict[str, np.ndarray] = {
    'flange': np.eye(4),
    'suction_tcp': translation(z=SUCTION_TCP_OFFSET_M),
}


class Zu12Kinematics(ArmKinematics):
    """FK and IK of the Zu 12 for one tool frame. ``world_to_base`` (4x4), when the base is
    fixed in the world, lets targets be given in the ``world`` frame."""

    def __init__(self, tool_frame: str = 'suction_tcp',
                 world_to_base: Optional[np.ndarray] = None) -> None:
        frames = {'base_link': np.eye(4)}
        if world_to_base is not None:
            frames['world'] = np.linalg.inv(np.asarray(world_to_base, float))
        super().__init__(zu12_chain(), solve_ik, JOINT_NAMES, JOINT_VELOCITY_LIMITS, np.eye(4),
                         TOOL_FRAMES, tool_frame, frames, min_frame_height=FLOOR_CLEARANCE_M)
