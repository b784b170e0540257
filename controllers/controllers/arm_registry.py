"""The arm model registry (no ROS): an arm's kinematics from its description, whatever the
arm. This is the one place that knows robot models by their kinematics: the analytic solvers
of the JAKA Zu 12 and the KUKA youBot's arm are registered here as fast paths. An arm whose
URDF chain has the same forward kinematics as a registered solver's (at postures spread over
its joint limits, within 1e-9) and the same joint limits is solved by it; any other serial arm
by the generic solver (controllers/urdf_arm.py). An arm is found by what its URDF describes,
not by its name.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple, Union

import numpy as np

from controllers.arm_model import ArmKinematics
from controllers.urdf_arm import UrdfArm
from controllers.youbot_kinematics import YoubotKinematics
from controllers.zu12_kinematics import Zu12Kinematics

Kinematics = Union[ArmKinematics, UrdfArm]
# Postures a fast path's forward kinematics is compared at, and the agreement asked [m].
MATCH_POSTURES = 12
MATCH_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ArmSpec:
    """An arm as a world describes it: its URDF, the joints its arm controller drives (in that
    order), its tool (a link and an offset in the link's frame [m]), whether the tool may turn
    freely about its z axis (a suction cup), and where its base stands in the world (x, y, z,
    yaw; a fixed base: targets may then be given in ``world``)."""

    urdf: Path
    joints: Tuple[str, ...]
    tool_link: str
    tool_offset: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    free_yaw: bool = False
    base_pose: Optional[Tuple[float, float, float, float]] = None
    # The floor's clearance asked of every joint but the first [m] (a fixed base on the floor).
    floor_clearance: float = 0.02
    # The posture the generic solver keeps the arm nearest where the task leaves it free (its
    # home; None: the middle of its limits).
    preferred: Optional[Tuple[float, ...]] = None
    fast_paths: bool = field(default=True, compare=False)


@dataclass(frozen=True)
class FastPath:
    """An analytic solver: a factory of its kinematics for a tool frame of its own."""

    name: str
    make: Callable[[str, Optional[np.ndarray]], ArmKinematics]
    tool_frames: Tuple[str, ...]


FAST_PATHS: Tuple[FastPath, ...] = (
    FastPath('JAKA Zu 12 (analytic)', lambda tool, world: Zu12Kinematics(tool, world),
             ('suction_tcp', 'flange')),
    FastPath('KUKA youBot arm (analytic)', lambda tool, world: YoubotKinematics(tool),
             ('gripper_tcp', 'arm_link_5')),
)


def planar_pose(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """4x4 of a pose standing upright at (x, y, z), turned ``yaw`` about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, z],
                     [0.0, 0.0, 0.0, 1.0]])


def generic_kinematics(spec: ArmSpec) -> UrdfArm:
    """The generic solver of the arm (controllers/urdf_arm.py)."""
    frames: Dict[str, np.ndarray] = {}
    floor = None
    if spec.base_pose is not None:
        frames['world'] = np.linalg.inv(planar_pose(*spec.base_pose))
        floor = -spec.base_pose[2] + spec.floor_clearance
    return UrdfArm(spec.urdf, spec.joints, spec.tool_link, spec.tool_offset, spec.free_yaw,
                   floor, frames, spec.preferred)


def arm_kinematics(spec: ArmSpec) -> Tuple[Kinematics, str]:
    """The arm's kinematics and the solver's name: a registered fast path whose kinematics are
    the URDF's, else the generic solver."""
    generic = generic_kinematics(spec)
    if spec.fast_paths:
        world = None if spec.base_pose is None else planar_pose(*spec.base_pose)
        for fast in FAST_PATHS:
            kin = _matching(fast, generic, world)
            if kin is not None:
                return kin, fast.name
    return generic, 'generic (pinocchio, damped least squares)'


def _matching(fast: FastPath, generic: UrdfArm, world: Optional[np.ndarray]
              ) -> Optional[ArmKinematics]:
    for tool in fast.tool_frames:
        kin = fast.make(tool, world)
        if not same_kinematics(kin, generic):
            continue
        if world is not None and 'world' not in kin.reference_frames:
            return None         # (a fast path for mobile arms only)
        kin.joint_names = generic.joint_names
        return kin
    return None


def same_kinematics(a: Kinematics, b: Kinematics,
                    postures: int = MATCH_POSTURES) -> bool:
    """Whether two arms' joints, limits and forward kinematics agree (at ``postures`` postures
    drawn over the limits, the same every time)."""
    if len(a.joint_names) != len(b.joint_names):
        return False
    if not (np.allclose(a.lower, b.lower, atol=1e-9) and np.allclose(a.upper, b.upper,
                                                                    atol=1e-9)):
        return False
    rng = np.random.default_rng(0)
    for _ in range(postures):
        q = rng.uniform(a.lower, a.upper)
        if float(np.abs(a.fk(q) - b.fk(q)).max()) > MATCH_TOLERANCE:
            return False
    return True
