"""The cell's arms as data (no ROS): each arm's model read from its world entry (its URDF, the
joints its arm controller drives, its grip tool as the tool frame, where its base stands, its
joint limits), and its kinematics from the model registry (controllers/arm_registry.py): an
analytic fast path where one is registered for the URDF's chain, else the generic solver."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

import numpy as np

from controllers.arm_registry import ArmSpec, Kinematics, arm_kinematics
from controllers.time_optimal import JointLimits
from controllers.urdf_arm import UrdfArmError
from world_description.joint_limits import JointLimitsError, load_joint_limits
from world_description.resources import resolve_resource

# The controller that moves a robot's arm (the simulator's joint group of that name).
ARM_CONTROLLER = 'arm_controller'
# Without a joint_limits file giving them, an arm's joints accelerate at most this many times
# their speed limit per second, and their jerk is JERK_PER_ACCELERATION times that (the
# assumption made for the Zu 12, whose maker publishes neither: of the order of other cobots').
ACCELERATION_PER_SPEED = 4.0
JERK_PER_ACCELERATION = 10.0


class ArmModelError(ValueError):
    """An arm the world describes that the cell cannot use (one line)."""


@dataclass(frozen=True)
class ArmModel:
    """An arm of the cell: its kinematic model and its joints' limits for planning: velocity
    from the URDF (or lower, from its controller's joint_limits file), acceleration and jerk
    from that file (else ACCELERATION_PER_SPEED times the velocity, and JERK_PER_ACCELERATION
    times that)."""

    spec: ArmSpec
    velocity: Tuple[float, ...]
    acceleration: Tuple[float, ...]
    jerk: Tuple[float, ...]

    def limits(self, scaling: float = 1.0) -> JointLimits:
        """The planner's limits, the velocity scaled by ``scaling``, the positions the URDF's."""
        kin = self.kinematics
        return JointLimits(np.asarray(self.velocity), np.asarray(self.acceleration),
                           np.asarray(self.jerk), np.asarray(kin.lower, float),
                           np.asarray(kin.upper, float)).scaled(scaling)

    @property
    def kinematics(self) -> Kinematics:
        return kinematics_of(self.spec)

    @property
    def solver(self) -> str:
        return solver_of(self.spec)


@lru_cache(maxsize=None)
def _solved(spec: ArmSpec) -> Tuple[Kinematics, str]:
    return arm_kinematics(spec)


def kinematics_of(spec: ArmSpec) -> Kinematics:
    """The arm's kinematics (made once per model)."""
    return _solved(spec)[0]


def solver_of(spec: ArmSpec) -> str:
    """Which solver serves the arm: a registered fast path's name, or the generic one's."""
    return _solved(spec)[1]


def arm_model(robot: Any, base_dir: Optional[Path] = None, fixed: Optional[bool] = None
              ) -> ArmModel:
    """The model of a world's robot (world_description's RobotConfig) with an arm controller
    and a grip tool; ``fixed`` (default: the robot's fixed_base): targets may be given in the
    world frame. An ArmModelError names what is missing."""
    arm = next((c for c in robot.controllers if c.name == ARM_CONTROLLER), None)
    if arm is None:
        raise ArmModelError(f'robot {robot.name}: it has no {ARM_CONTROLLER}')
    if robot.suction is None:
        raise ArmModelError(f'robot {robot.name}: it has no grip tool (suction)')
    tool = robot.suction
    fixed = robot.fixed_base if fixed is None else fixed
    pose = robot.pose
    initial = dict(robot.initial_joint_positions)
    home = tuple(initial[j] for j in arm.joints) if all(j in initial for j in arm.joints) \
        else None
    spec = ArmSpec(resolve_resource(robot.urdf, base_dir), tuple(arm.joints), tool.link,
                   tuple(tool.offset), tool.free_yaw,
                   (pose.x, pose.y, pose.z, pose.yaw) if fixed else None, preferred=home)
    try:
        kin = kinematics_of(spec)
    except UrdfArmError as exc:
        raise ArmModelError(f'robot {robot.name}: {exc}') from None
    given: Dict[str, Dict[str, float]] = {}
    if arm.joint_limits:
        try:
            given = load_joint_limits(resolve_resource(arm.joint_limits, base_dir))
        except JointLimitsError as exc:
            raise ArmModelError(f'robot {robot.name}: {exc}') from None
    urdf = [float(v) for v in kin.velocity_limits]
    velocity = tuple(min(v, given.get(j, {}).get('velocity', v)) for j, v in zip(spec.joints,
                                                                                  urdf))
    acceleration = tuple(given.get(j, {}).get('acceleration', ACCELERATION_PER_SPEED * v)
                         for j, v in zip(spec.joints, velocity))
    jerk = tuple(given.get(j, {}).get('jerk', JERK_PER_ACCELERATION * a)
                 for j, a in zip(spec.joints, acceleration))
    return ArmModel(spec, velocity, acceleration, jerk)
