"""How a robot of the world is moved: its drive (a differential or a Mecanum base, wheel speeds
from a twist) and its joint groups (each a trajectory follower with PD gains), on any body
that gives them its joints (``ActuatedBody``; robot.py's SimRobot)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import FrozenSet, List, Optional, Protocol, Sequence, Tuple

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.diff_drive import DiffDriveGeometry
from controllers.diff_drive import wheel_speeds as diff_wheel_speeds
from controllers.joint_trajectory import JointLimits, TrajectoryFollower
from controllers.mecanum import MecanumGeometry
from controllers.mecanum import wheel_speeds as mecanum_wheel_speeds
from sim_bridge.errors import WorldError
from sim_bridge.sensors import RobotSensors
from world_description.joint_limits import JointLimitsError, load_acceleration_limits
from world_description.resources import resolve_resource
from world_description.world_config import (
    ControllerConfig,
    DiffDriveConfig,
    MecanumConfig,
    RobotConfig,
)

# A virtual omni-wheel's joint turns 1/sqrt(2) as fast as the Mecanum wheel it stands for.
OMNI_WHEEL_SCALE = math.sqrt(2.0)


class ActuatedBody(Protocol):
    """What a drive and a joint group need of the body they move."""

    config: RobotConfig
    client: BulletClient
    body: int
    sensors: RobotSensors            # what its encoders report (sensors.py)

    def movable_joint(self, joint: str, what: str) -> int: ...

    def joint_limits(self, joint: str) -> Tuple[float, float, float, float]: ...

    def links_moved_by(self, joints: Sequence[int]) -> FrozenSet[int]: ...

    def link_name(self, link: int) -> str: ...


def _wheel_limit(robot: ActuatedBody, *joints: str) -> float:
    """The slowest of the wheels' URDF speed limits [rad/s] (inf: none gives one)."""
    limits = [robot.joint_limits(j)[2] for j in joints]
    return min((v for v in limits if v > 0.0), default=math.inf)


class DiffDrive:
    def __init__(self, robot: ActuatedBody, config: DiffDriveConfig) -> None:
        self._robot, self.config = robot, config
        self.joints = tuple(robot.movable_joint(j, 'drive')
                            for j in (config.left_wheel_joint, config.right_wheel_joint))
        self.geometry = DiffDriveGeometry(config.wheel_radius, config.wheel_separation)
        self.components = ('linear.x', 'angular.z')
        self.targets: Tuple[float, ...] = (0.0, 0.0)
        self.wheel_limit = _wheel_limit(robot, config.left_wheel_joint, config.right_wheel_joint)

    def wheel_speeds(self, command: Tuple[float, ...]) -> Tuple[float, ...]:
        """The wheels' speeds [rad/s] for a (vx, vy, wz) command."""
        return tuple(diff_wheel_speeds(command[0], command[2], self.geometry))

    def command(self, vx: float, vy: float, wz: float) -> Tuple[float, ...]:
        del vy                                     # a differential drive cannot strafe
        targets = diff_wheel_speeds(vx, wz, self.geometry)
        p = self._robot.client
        for joint, target in zip(self.joints, targets):
            p.setJointMotorControl2(self._robot.body, joint, pybullet.VELOCITY_CONTROL,
                                    targetVelocity=target, force=self.config.wheel_effort)
        self.targets = targets
        return targets


class MecanumDrive:
    """Four virtual omni-wheels: spheres spinning about the contact roller's axis.

    A Mecanum wheel turning at u (forward-positive) leaves its contact free along the roller
    axis and drives it across the roller at r*u*cos(45 deg). The sphere spins about the roller
    axis (its link y, see the youBot URDF), frictionless along it, so its joint runs at
    u/sqrt(2); the reported wheel angle and speed are sqrt(2) times the joint's.
    """

    def __init__(self, robot: ActuatedBody, config: MecanumConfig) -> None:
        self._robot, self.config = robot, config
        self.joints = tuple(robot.movable_joint(j, 'drive') for j in config.wheel_joints)
        self.geometry = MecanumGeometry(config.wheel_radius,
                                        config.sum_of_robot_center_projection_on_X_Y_axis)
        self.components = ('linear.x', 'linear.y', 'angular.z')
        self.targets: Tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)
        self.wheel_limit = _wheel_limit(robot, *config.wheel_joints)
        for joint in self.joints:
            # No friction along the spin axis (link y), which the spin leaves fixed in space.
            robot.client.changeDynamics(robot.body, joint, anisotropicFriction=(1.0, 0.0, 1.0),
                                    lateralFriction=1.0)
            robot.sensors.scale_reported_angle(joint, OMNI_WHEEL_SCALE)

    def wheel_speeds(self, command: Tuple[float, ...]) -> Tuple[float, ...]:
        """The Mecanum wheels' speeds [rad/s] for a (vx, vy, wz) command."""
        vx, vy, wz = command
        return tuple(mecanum_wheel_speeds(vx, vy, wz, self.geometry))

    def command(self, vx: float, vy: float, wz: float) -> Tuple[float, ...]:
        targets = mecanum_wheel_speeds(vx, vy, wz, self.geometry)
        p = self._robot.client
        for joint, target in zip(self.joints, targets):
            p.setJointMotorControl2(self._robot.body, joint, pybullet.VELOCITY_CONTROL,
                                    targetVelocity=target / OMNI_WHEEL_SCALE,
                                    force=self.config.wheel_effort)
        self.targets = targets
        return targets


class JointGroup:
    """Position-controlled joints following trajectories (PyBullet position motors)."""

    def __init__(self, robot: ActuatedBody, config: ControllerConfig,
                 base_dir: Optional[Path] = None) -> None:
        self._robot, self.config = robot, config
        self.joint_names = config.joints
        self.joints = [robot.movable_joint(j, f'controller "{config.name}"')
                       for j in config.joints]
        limits = [robot.joint_limits(j) for j in config.joints]
        for joint, (_, _, velocity, effort) in zip(config.joints, limits):
            if not (velocity > 0.0 and effort > 0.0):
                raise WorldError(f'robot "{robot.config.name}": controller "{config.name}": '
                                 f'joint "{joint}" needs velocity and effort limits > 0 in the '
                                 'URDF')
        accelerations = np.full(len(limits), np.inf)
        if config.joint_limits is not None:
            source = resolve_resource(config.joint_limits, base_dir)
            try:
                given = load_acceleration_limits(source)
            except JointLimitsError as exc:
                raise WorldError(f'robot "{robot.config.name}": controller "{config.name}": '
                                 f'{exc}') from None
            accelerations = np.array([given.get(j, np.inf) for j in config.joints])
        lower, upper, velocities, efforts = [np.array([lim[i] for lim in limits])
                                             for i in range(4)]
        self.limits = JointLimits(lower, upper, velocities, efforts, accelerations)
        # Per joint; 0: not checked (JTC's constraints.<joint>.trajectory).
        self.path_tolerance = np.full(len(limits), config.path_tolerance)
        # The tolerances of the trajectory being followed (an action goal may set its own).
        self.active_path_tolerance = self.path_tolerance
        # Why the group stopped following on its own (a reference that is not finite); the
        # runner reports and clears it.
        self.fault = ''
        self.moved_links = robot.links_moved_by(self.joints)
        self._effort = self.limits.effort.tolist()
        self._max_velocity = self.limits.velocity.tolist()
        # As last sent to PyBullet:
        self._motor_targets: Optional[Tuple[List[float], List[float]]] = None
        self.follower = TrajectoryFollower(config.joints, self.limits, np.zeros(len(limits)))
        self.desired = self.follower.sample(0.0)

    @property
    def robot(self) -> ActuatedBody:
        return self._robot

    def hold_current(self) -> None:
        self.follower.hold(self._robot.sensors.joint_positions(self.joint_names))
        self.desired = self.follower.sample(0.0)
        self._motor_targets = None

    def apply(self, t: float) -> None:
        self.desired = state = self.follower.sample(t)
        # PyBullet keeps a motor's settings until they are set again: a group holding still
        # is not sent the same targets 240 times a second.
        targets = (state.positions.tolist(), state.velocities.tolist())
        if targets == self._motor_targets:
            return
        if not math.isfinite(sum(targets[0]) + sum(targets[1])):
            # (Validation keeps this out; if it ever comes, it must not reach PyBullet.)
            self.fault = 'its reference is not finite'
            self.hold_current()
            return
        self._motor_targets = targets
        p, body = self._robot.client, self._robot.body
        c = self.config
        effort, velocity = self._effort, self._max_velocity
        for i, joint in enumerate(self.joints):
            p.setJointMotorControl2(body, joint, pybullet.POSITION_CONTROL,
                                    targetPosition=targets[0][i]
                                    + self._robot.sensors.encoder_offset(joint),
                                    targetVelocity=targets[1][i],
                                    force=effort[i], maxVelocity=velocity[i],
                                    positionGain=c.position_gain, velocityGain=c.velocity_gain)

    def actual(self) -> Tuple[np.ndarray, np.ndarray]:
        return (self._robot.sensors.joint_positions(self.joint_names),
                self._robot.sensors.joint_velocities(self.joint_names))
