"""The PyBullet world: loads a WorldConfig, steps physics, drives bases, renders cameras."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import (
    Any,
    Callable,
    Dict,
    FrozenSet,
    List,
    Optional,
    Sequence,
    Set,
    Tuple,
    Union,
    cast,
)

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.diff_drive import DiffDriveGeometry
from controllers.diff_drive import wheel_speeds as diff_wheel_speeds
from controllers.joint_trajectory import JointLimits, TrajectoryFollower
from controllers.mecanum import MecanumGeometry
from controllers.mecanum import wheel_speeds as mecanum_wheel_speeds
from controllers.transforms import rpy_matrix, yaw_from_quaternion
from sim_bridge.backdrop import StaticBackdrop, static_visuals
from sim_bridge.camera import perturb_frame, projection_matrix, view_matrix_from_optical
from sim_bridge.cell import Conveyor, MaterialBody, MaterialSource, Suction
from sim_bridge.client import Client
from sim_bridge.free_bodies import Lost, base_problem, moving_within_reason
from sim_bridge.joint_speed import Braked, SpeedLimiter
from world_description.camera_geometry import intrinsics_from_fov, look_at_rotation
from world_description.joint_limits import JointLimitsError, load_acceleration_limits
from world_description.perturbations import PerturbationDraws
from world_description.resources import resolve_resource
from world_description.world_config import (
    CameraConfig,
    ControllerConfig,
    DiffDriveConfig,
    MecanumConfig,
    RobotConfig,
    WorldConfig,
)

FLOOR_COLOR = (0.82, 0.80, 0.76, 1.0)
# Inertias as written in the URDF; true cylinders, because the convex hull PyBullet otherwise
# makes of a URDF cylinder rolls on its collision margin (a 2 % larger effective wheel radius).
URDF_FLAGS = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_USE_IMPLICIT_CYLINDER
# A virtual omni-wheel's joint turns 1/sqrt(2) as fast as the Mecanum wheel it stands for.
OMNI_WHEEL_SCALE = math.sqrt(2.0)


# A pose as PyBullet gives it: position, quaternion (x, y, z, w).
Transform = Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]

class WorldError(RuntimeError):
    """The world cannot be built (missing URDF, unknown joint or link)."""


@dataclass
class JointStates:
    names: List[str]
    positions: List[float]
    velocities: List[float]
    efforts: List[float]


@dataclass
class BaseState:
    """Pose of base_link in the robot's odom frame (its start pose), twist in base_link."""

    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]  # x, y, z, w
    linear: Tuple[float, float, float]
    angular: Tuple[float, float, float]


class SimRobot:
    """One URDF body: its joints, its base frame, its drive and its joint-group controllers."""

    def __init__(self, client: BulletClient, config: RobotConfig, urdf: Path,
                 base_dir: Optional[Path] = None, time_step: float = 1.0 / 240.0) -> None:
        self.config = config
        self.client = client
        self.time_step = time_step
        if not urdf.is_file():
            raise WorldError(f'robot "{config.name}": URDF {urdf} does not exist')
        self.urdf = urdf
        self._base_dir = base_dir
        pose = config.pose
        self._start_pos = (pose.x, pose.y, pose.z)
        self._start_orn = tuple(client.getQuaternionFromEuler((0.0, 0.0, pose.yaw)))
        # Perturbations (set_perturbations): each joint's offset [rad] between where it is and
        # where its encoder says (by PyBullet index), and the factors the odometry gets its x,
        # y and yaw motion wrong by.
        self._encoder_offset: Dict[int, float] = {}
        self.odometry_scale = (1.0, 1.0, 1.0)
        self._load()

    def set_perturbations(self, joint_offsets: Dict[str, float],
                          odometry_scale: Tuple[float, float, float]) -> None:
        """A mis-calibrated robot: each joint in ``joint_offsets`` sits that far [rad] from
        where its encoder (the joint states, its controller) says, and its odometry reports
        its motion times ``odometry_scale`` (x, y, yaw). Takes effect from a reset on."""
        self._encoder_offset = {self.movable_joint(j, 'perturbations'): float(v)
                                for j, v in joint_offsets.items() if v != 0.0}
        self.odometry_scale = odometry_scale

    def encoder_offset(self, joint: int) -> float:
        """How far [rad] a joint (PyBullet index) is from where its encoder says."""
        return self._encoder_offset.get(joint, 0.0)

    def _load(self) -> None:
        """Load the URDF at the start pose and set up its joints, drive and controllers."""
        client, config = self.client, self.config
        try:
            self.body = client.loadURDF(str(self.urdf), self._start_pos, self._start_orn,
                                        useFixedBase=config.fixed_base, flags=URDF_FLAGS)
        except pybullet.error as exc:
            raise WorldError(
                f'robot "{config.name}": PyBullet cannot load {self.urdf}: {exc}') from None
        # PyBullet reports the base's inertial frame; keep its offset from base_link.
        info = client.getDynamicsInfo(self.body, -1)
        self._inertial_pos, self._inertial_orn = info[3], info[4]
        self.joint_index: Dict[str, int] = {}
        self.link_index: Dict[str, int] = {client.getBodyInfo(self.body)[0].decode(): -1}
        self.movable: List[int] = []
        self.revolute: Set[str] = set()           # the names of the revolute joints
        self._joint_names: List[str] = []
        self._joint_limits: Dict[str, Tuple[float, float, float, float]] = {}
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            name, jtype = info[1].decode(), info[2]
            self.joint_index[name] = j
            self.link_index[info[12].decode()] = j
            if jtype == pybullet.JOINT_REVOLUTE:
                self.revolute.add(name)
            if jtype != pybullet.JOINT_FIXED:
                self.movable.append(j)
                self._joint_names.append(name)
                lower, upper = info[8], info[9]
                if lower > upper:                     # continuous: PyBullet reports 0, -1
                    lower, upper = -math.inf, math.inf
                self._joint_limits[name] = (lower, upper, info[11], info[10])
                # Free joints by default; PyBullet otherwise brakes each one with a motor.
                client.setJointMotorControl2(self.body, j, pybullet.VELOCITY_CONTROL, force=0.0)
        # Reported wheel angle per joint = scale * PyBullet joint angle (virtual omni-wheels).
        self._report_scale = np.ones(len(self.movable))
        self.drive: Optional[Union[_DiffDrive, _MecanumDrive]] = None
        if isinstance(config.drive, DiffDriveConfig):
            self.drive = _DiffDrive(self, config.drive)
        elif isinstance(config.drive, MecanumConfig):
            self.drive = _MecanumDrive(self, config.drive)
        self.controllers: Dict[str, JointGroup] = {}
        for cc in config.controllers:
            self.controllers[cc.name] = JointGroup(self, cc, self._base_dir)
        # No joint faster than its URDF limit, whatever drives it (joint_speed.py).
        self.speed_limiter = SpeedLimiter(
            client, self.body, self.movable, self._joint_names,
            [self._joint_limits[n][2] for n in self._joint_names], self._report_scale.tolist(),
            floating_base=not config.fixed_base, time_step=self.time_step,
            prismatic=[n not in self.revolute for n in self._joint_names],
            efforts=[self._joint_limits[n][3] for n in self._joint_names])
        self._initial: Dict[int, float] = {}
        for joint, position in config.initial_joint_positions:
            j = self.movable_joint(joint, 'initial_joint_positions')
            lower, upper = self._joint_limits[joint][:2]
            if not lower <= position <= upper:
                raise WorldError(f'robot "{config.name}": initial position {position} of '
                                 f'"{joint}" is outside its limits [{lower}, {upper}]')
            self._initial[j] = position
        self.reset()

    def state_problem(self, joints: bool = True) -> str:
        """What in the body's state is not finite, or has left the world ('' if nothing is):
        PyBullet carries a NaN on from step to step, and resetting the state does not clear it
        from the body. ``joints=False``: the base's velocity only (after every step)."""
        p, body = self.client, self.body
        problem = base_problem(p, body, pose=joints)
        if problem:
            return f'its base: {problem}'
        if not joints:
            return ''
        states = p.getJointStates(body, self.movable) if self.movable else []
        bad = [self._joint_names[i] for i, st in enumerate(states)
               if not math.isfinite(st[0] + st[1])]
        return f'the states of joints {bad} are not finite' if bad else ''

    def reload(self) -> None:
        """Remove the body from the physics and load it again at its start pose, at rest: the
        one way back from a non-finite state. Controllers start anew, holding."""
        self.client.removeBody(self.body)
        self._load()

    @property
    def joint_names(self) -> List[str]:
        return list(self._joint_names)

    @property
    def wheel_targets(self) -> Tuple[float, ...]:
        return self.drive.targets if self.drive is not None else ()

    @property
    def geometry(self) -> Any:
        """The drive's kinematic geometry (DiffDriveGeometry or MecanumGeometry), or None."""
        return self.drive.geometry if self.drive is not None else None

    def joint_limits(self, joint: str) -> Tuple[float, float, float, float]:
        """(lower, upper, max velocity, max effort) as the URDF gives them."""
        return self._joint_limits[joint]

    def drive_wheel_limit(self) -> float:
        """The speed limit [rad/s] of the drive's slowest wheel."""
        return self.drive.wheel_limit if self.drive is not None else math.inf

    def set_body_twist(self, vx: float, vy: float, wz: float) -> Tuple[float, ...]:
        """Command the wheel velocity motors for a body twist; returns the wheel targets
        (a differential drive ignores vy)."""
        if self.drive is None:
            raise WorldError(f'robot "{self.config.name}" has no drive')
        return self.drive.command(vx, vy, wz)

    def apply_controllers(self, t: float) -> None:
        for group in self.controllers.values():
            group.apply(t)

    def link_name(self, link: int) -> str:
        if link < 0:
            return self._root_link()
        return str(self.client.getJointInfo(self.body, link)[12].decode())

    def links_moved_by(self, joints: Sequence[int]) -> FrozenSet[int]:
        """The links (PyBullet link indices) downstream of any of these joints."""
        moved = set(joints)
        for link in range(self.client.getNumJoints(self.body)):   # (parents come first)
            if self.client.getJointInfo(self.body, link)[16] in moved:
                moved.add(link)
        return frozenset(moved)

    def joint_states(self) -> JointStates:
        states = self.client.getJointStates(self.body, self.movable)
        scale = self._report_scale
        off = [self._encoder_offset.get(j, 0.0) for j in self.movable]
        # A virtual omni-wheel turns 1/sqrt(2) as fast with sqrt(2) times the torque (same power).
        return JointStates(self.joint_names, [s[0] * k - o for s, k, o in zip(states, scale, off)],
                           [s[1] * k for s, k in zip(states, scale)],
                           [s[3] / k for s, k in zip(states, scale)])

    def joint_positions(self, joints: Sequence[str]) -> np.ndarray:
        """Where the joints' encoders say they are."""
        index = [self.joint_index[j] for j in joints]
        states = self.client.getJointStates(self.body, index)
        return np.array([s[0] - self._encoder_offset.get(j, 0.0) for s, j in zip(states, index)])

    def joint_velocities(self, joints: Sequence[str]) -> np.ndarray:
        states = self.client.getJointStates(self.body, [self.joint_index[j] for j in joints])
        return np.array([s[1] for s in states])

    def base_link_world(self) -> Transform:
        com_pos, com_orn = self.client.getBasePositionAndOrientation(self.body)
        inv_pos, inv_orn = self.client.invertTransform(self._inertial_pos, self._inertial_orn)
        return cast(Transform, self.client.multiplyTransforms(com_pos, com_orn, inv_pos,
                                                              inv_orn))

    def base_state(self) -> BaseState:
        pos, orn = self.base_link_world()
        com_pos, _ = self.client.getBasePositionAndOrientation(self.body)
        v_com, omega = self.client.getBaseVelocity(self.body)
        # Velocity of the base_link origin, not of the centre of mass.
        v_link = np.asarray(v_com) + np.cross(omega, np.subtract(pos, com_pos))
        rot = np.array(self.client.getMatrixFromQuaternion(orn)).reshape(3, 3)
        # Pose relative to the start pose, which is the odom frame's origin.
        inv_pos, inv_orn = self.client.invertTransform(self._start_pos, self._start_orn)
        odom_pos, odom_orn = self.client.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        linear, angular = rot.T @ v_link, rot.T @ np.asarray(omega)
        sx, sy, syaw = self.odometry_scale
        if (sx, sy, syaw) != (1.0, 1.0, 1.0):
            # Odometry that drifts: its pose and twist off by a scale per axis.
            yaw = yaw_from_quaternion(odom_orn)
            extra = self.client.getQuaternionFromEuler((0.0, 0.0, yaw * (syaw - 1.0)))
            _, turned = self.client.multiplyTransforms((0.0, 0.0, 0.0), extra, (0.0, 0.0, 0.0),
                                                       odom_orn)
            odom_pos, odom_orn = (odom_pos[0] * sx, odom_pos[1] * sy, odom_pos[2]), turned
            linear, angular = linear * (sx, sy, 1.0), angular * (1.0, 1.0, syaw)
        return BaseState(tuple(odom_pos), tuple(odom_orn), tuple(linear), tuple(angular))

    def link_world_pose(self, link: str) -> Tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of a link frame (URDF frame, not inertial)."""
        if link not in self.link_index:
            raise WorldError(f'robot "{self.config.name}" has no link "{link}"')
        index = self.link_index[link]
        if index == -1:
            pos, orn = self.base_link_world()
        else:
            state = self.client.getLinkState(self.body, index, computeForwardKinematics=True)
            pos, orn = state[4], state[5]
        return np.asarray(pos), np.array(self.client.getMatrixFromQuaternion(orn)).reshape(3, 3)

    def link_pose_in_base(self, link: str) -> np.ndarray:
        """4x4 pose of a link frame in base_link (ground truth of the simulation)."""
        base_pos, base_rot = self.link_world_pose(self._root_link())
        pos, rot = self.link_world_pose(link)
        out = np.eye(4)
        out[:3, :3] = base_rot.T @ rot
        out[:3, 3] = base_rot.T @ (pos - base_pos)
        return out

    def reset(self) -> None:
        self.client.resetBasePositionAndOrientation(self.body, *self._start_com())
        self.client.resetBaseVelocity(self.body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        for j in self.movable:
            self.client.resetJointState(
                self.body, j, self._initial.get(j, 0.0) + self._encoder_offset.get(j, 0.0), 0.0)
        if self.drive is not None:
            self.drive.command(0.0, 0.0, 0.0)
        for group in self.controllers.values():
            group.hold_current()

    @property
    def start_pose(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
        """base_link's pose in the world at start: the odom frame of a mobile robot."""
        return self._start_pos, self._start_orn

    def _root_link(self) -> str:
        return next(name for name, index in self.link_index.items() if index == -1)

    def pose_as_reported(self, names: Sequence[str], positions: Sequence[float]) -> None:
        """Put the joints where joint states that said ``positions`` found them (the inverse
        of :meth:`joint_states`: its encoder offsets and reporting scales undone); names it
        does not have are left out. To show a recorded moment, not to simulate on from it."""
        for name, reported in zip(names, positions):
            j = self.joint_index.get(name)
            if j is None or j not in self.movable or not math.isfinite(reported):
                continue
            scale = float(self._report_scale[self.movable.index(j)])
            self.client.resetJointState(self.body, j,
                                        (reported + self._encoder_offset.get(j, 0.0)) / scale)

    def place_as_reported(self, position: Sequence[float],
                          orientation: Sequence[float]) -> None:
        """Put the base where odometry that said ``position``, ``orientation`` (x, y, z, w; in
        the odom frame) found it: the inverse of :meth:`base_state` (its scale errors undone).
        A pose that is not finite leaves the base where it is."""
        if not all(math.isfinite(v) for v in (*position, *orientation)):
            return
        sx, sy, syaw = self.odometry_scale
        p = self.client
        pos = (position[0] / sx, position[1] / sy, position[2])
        yaw = yaw_from_quaternion(orientation)
        undo = p.getQuaternionFromEuler((0.0, 0.0, yaw * (1.0 / syaw - 1.0)))
        _, orn = p.multiplyTransforms((0.0, 0.0, 0.0), undo, (0.0, 0.0, 0.0), orientation)
        world_pos, world_orn = p.multiplyTransforms(self._start_pos, self._start_orn, pos, orn)
        com = p.multiplyTransforms(world_pos, world_orn, self._inertial_pos, self._inertial_orn)
        p.resetBasePositionAndOrientation(self.body, *com)

    def scale_reported_angle(self, joint: int, scale: float) -> None:
        """Report this movable joint's angle and speed times ``scale`` (a virtual omni-wheel
        turns 1/sqrt(2) as fast as the Mecanum wheel it stands for)."""
        self._report_scale[self.movable.index(joint)] = scale

    def movable_joint(self, joint: str, what: str) -> int:
        """The PyBullet index of the movable joint named ``joint`` (WorldError naming ``what``
        needs it when there is none)."""
        j = self.joint_index.get(joint)
        if j is None or j not in self.movable:
            raise WorldError(f'robot "{self.config.name}": {what}: "{joint}" is not a movable '
                             f'joint of the URDF (movable: {self._joint_names})')
        return j

    def _start_com(self) -> Transform:
        return cast(Transform, self.client.multiplyTransforms(
            self._start_pos, self._start_orn, self._inertial_pos, self._inertial_orn))


def _wheel_limit(robot: SimRobot, *joints: str) -> float:
    """The slowest of the wheels' URDF speed limits [rad/s] (inf: none gives one)."""
    limits = [robot.joint_limits(j)[2] for j in joints]
    return min((v for v in limits if v > 0.0), default=math.inf)


class _DiffDrive:
    def __init__(self, robot: SimRobot, config: DiffDriveConfig) -> None:
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


class _MecanumDrive:
    """Four virtual omni-wheels: spheres spinning about the contact roller's axis.

    A Mecanum wheel turning at u (forward-positive) leaves its contact free along the roller
    axis and drives it across the roller at r*u*cos(45 deg). The sphere spins about the roller
    axis (its link y, see the youBot URDF), frictionless along it, so its joint runs at
    u/sqrt(2); the reported wheel angle and speed are sqrt(2) times the joint's.
    """

    def __init__(self, robot: SimRobot, config: MecanumConfig) -> None:
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
            robot.scale_reported_angle(joint, OMNI_WHEEL_SCALE)

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

    def __init__(self, robot: SimRobot, config: ControllerConfig,
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
    def robot(self) -> 'SimRobot':
        return self._robot

    def hold_current(self) -> None:
        self.follower.hold(self._robot.joint_positions(self.joint_names))
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
                                    + self._robot.encoder_offset(joint),
                                    targetVelocity=targets[1][i],
                                    force=effort[i], maxVelocity=velocity[i],
                                    positionGain=c.position_gain, velocityGain=c.velocity_gain)

    def actual(self) -> Tuple[np.ndarray, np.ndarray]:
        return (self._robot.joint_positions(self.joint_names),
                self._robot.joint_velocities(self.joint_names))


class SimCamera:
    def __init__(self, config: CameraConfig, robot: Optional[SimRobot],
                 pose_error: Optional[Tuple[np.ndarray, np.ndarray]] = None) -> None:
        """``pose_error``: the camera's position [m] and rotation (about its optical axes)
        [rad] off the pose the world file gives it, which the vision is told (a mis-calibrated
        camera, a perturbation)."""
        self.config = config
        self.robot = robot
        offset, angles = pose_error if pose_error is not None else (np.zeros(3), np.zeros(3))
        self._offset = np.asarray(offset, float)
        self._tilt = rpy_matrix(*(float(a) for a in angles))
        self.intrinsics = intrinsics_from_fov(config.width, config.height,
                                              config.vertical_fov_deg)
        self._projection = projection_matrix(config.width, config.height,
                                             config.vertical_fov_deg, config.near, config.far)
        self._link = ''
        if robot is None:
            if config.position is None or config.look_at is None:
                raise WorldError(f'camera "{config.name}": a camera on no robot needs a position '
                                 'and a point to look at')
            self._fixed_view = self._view(np.asarray(config.position, float),
                                          look_at_rotation(config.position, config.look_at))
        elif config.link is None or config.link not in robot.link_index:
            raise WorldError(f'camera "{config.name}": robot "{robot.config.name}" has no link '
                             f'"{config.link}"')
        else:
            self._link = config.link

    def view_matrix(self) -> Tuple[float, ...]:
        if self.robot is None:
            return self._fixed_view
        pos, rot = self.robot.link_world_pose(self._link)
        return self._view(np.asarray(pos, float), np.asarray(rot, float))

    def _view(self, position: np.ndarray, rotation: np.ndarray) -> Tuple[float, ...]:
        """The view from an optical frame's pose, off it by the camera's pose error."""
        return view_matrix_from_optical(position + rotation @ self._offset,
                                        rotation @ self._tilt)

    @property
    def projection(self) -> Tuple[float, ...]:
        return self._projection


def build_floor(p: BulletClient, size: float) -> int:
    """Infinite collision plane, but only a plain finite patch is drawn: PyBullet's large
    textured plane is the biggest cost of a CPU-rendered frame."""
    plane = p.createCollisionShape(pybullet.GEOM_PLANE)
    visual = p.createVisualShape(pybullet.GEOM_BOX, halfExtents=(size / 2, size / 2, 0.0005),
                                 rgbaColor=FLOOR_COLOR, visualFramePosition=(0.0, 0.0, -0.0005))
    floor = p.createMultiBody(0.0, plane, visual)
    p.changeDynamics(floor, -1, lateralFriction=1.0)
    return int(floor)


class SimWorld:
    """Owns one PyBullet client. Every physics step goes through :meth:`step`."""

    def __init__(self, config: WorldConfig, time_step: float = 1.0 / 240.0,
                 gui: bool = False, scenario_seed: Optional[int] = None) -> None:
        if not (0.0 < time_step <= 0.1):
            raise ValueError(f'time_step must be within (0, 0.1] s, got {time_step}')
        self.config = config
        self.time_step = time_step
        self.step_count = 0
        self._p = Client(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        p = self._p
        p.setTimeStep(time_step)
        p.setGravity(0.0, 0.0, config.gravity)
        self._build_floor(config.floor_size)
        self._obstacle_names: Dict[int, str] = {}
        self.obstacles: Dict[int, Any] = {}          # body: its ObstacleConfig
        # Fixed cameras' static scenes in the default light, by camera (None: the static
        # bodies are drawn in each frame). False: every frame of every camera is drawn whole
        # (a reference).
        self.backdrops = True
        self._backdrops: Dict[str, Optional[StaticBackdrop]] = {}
        self._relit = False            # a frame was rendered with light arguments
        for obstacle in config.obstacles:
            self._add_obstacle(obstacle)
        base_dir = Path(config.source).parent if config.source else None
        # The world's perturbations, drawn from the scenario's seed (off unless the world file
        # turns them on).
        self.draws = PerturbationDraws(config.perturbations, scenario_seed if scenario_seed
                                       is not None else config.materials.seed
                                       if config.materials else 0)
        self.robots: Dict[str, SimRobot] = {}
        for rc in config.robots:
            robot = SimRobot(p, rc, resolve_resource(rc.urdf, base_dir), base_dir, time_step)
            if config.perturbations.robots.active:
                robot.set_perturbations(
                    self.draws.joint_offsets(rc.name, [j for c in rc.controllers
                                                       for j in c.joints if j in robot.revolute]),
                    self.draws.odometry_scale(rc.name))
                robot.reset()
            self.robots[rc.name] = robot
        self.cameras: List[SimCamera] = [
            SimCamera(cc, self.robots[cc.robot] if cc.robot else None,
                      self.draws.camera_pose_error(cc.name)) for cc in config.cameras]
        self.conveyor = Conveyor(p, config.conveyor) if config.conveyor else None
        # (The world file's reader holds materials to a conveyor to be placed on.)
        self.source = (MaterialSource(p, self.conveyor, config.materials, scenario_seed,
                                      self.draws)
                       if config.materials and self.conveyor else None)
        # Where every static body (floor, obstacles, the belt and its stands) belongs: a
        # non-finite robot state spreads NaN into the static bodies it touches, and a body
        # loaded again then falls through a floor whose pose is NaN.
        robot_bodies = {robot.body for robot in self.robots.values()}
        self._static_poses = {
            body: p.getBasePositionAndOrientation(body)
            for body in (p.getBodyUniqueId(i) for i in range(p.getNumBodies()))
            if body not in robot_bodies and p.getDynamicsInfo(body, -1)[0] == 0.0}
        # Their visual shapes, hidden while a fixed camera draws what moves (None: they cannot
        # be drawn again alike, and every frame is drawn whole).
        self._static_visuals = static_visuals(p, list(self._static_poses))
        # Bodies spawned into the world by others (entities.py): name, and what to call when
        # the world takes one out; and the bodies taken out since take_lost.
        self._guests: Dict[int, Tuple[str, Callable[[], None]]] = {}
        self._lost: List[Lost] = []
        self._braked: List[Tuple[str, float, List[Braked]]] = []
        self.suctions: Dict[str, Suction] = {}
        for name, robot in self.robots.items():
            sc = robot.config.suction
            if sc is not None:
                try:
                    self.suctions[name] = Suction(p, robot, sc.link, sc.reach, sc.max_payload)
                except ValueError as exc:
                    raise WorldError(str(exc)) from None

    @property
    def client(self) -> BulletClient:
        """The world's PyBullet client."""
        return self._p

    @property
    def sim_time(self) -> float:
        return self.step_count * self.time_step

    @property
    def sim_time_ns(self) -> int:
        # Integer nanoseconds so that lock-step time is exact after any number of steps.
        return self.step_count * round(self.time_step * 1e9)

    @property
    def materials(self) -> List[MaterialBody]:
        return self.source.materials if self.source is not None else []

    def step(self) -> None:
        for suction in self.suctions.values():
            suction.update(self.source)
        if self.conveyor is not None:
            held = {s.held.body for s in self.suctions.values() if s.held is not None}
            self.conveyor.carry([m.body for m in self.materials if m.body not in held],
                                self.time_step, sorted(held),
                                self.draws.belt_speed(self.conveyor.speed, self.sim_time))
            if self.source is not None:
                self.source.update(self.sim_time)
        self._p.stepSimulation()
        self.step_count += 1
        self.check_free_bodies(pose=False)
        for name, robot in self.robots.items():
            braked = robot.speed_limiter.enforce()
            if braked:
                self._braked.append((name, self.sim_time, braked))

    def take_braked(self) -> List[Tuple[str, float, List[Braked]]]:
        """The joints brought back to their speed limits since the last call: (robot, time [s],
        what was braked)."""
        braked, self._braked = self._braked, []
        return braked

    def adopt(self, body: int, name: str, forget: Callable[[], None]) -> None:
        """Watch a body spawned by another part (its ``name``): one that leaves the world is
        removed, and ``forget()`` called."""
        self._guests[body] = (name, forget)

    def disown(self, body: int) -> None:
        """Stop watching a body (its owner removes it)."""
        self._guests.pop(body, None)

    def check_free_bodies(self, pose: bool = True) -> None:
        """Take out every material and spawned body whose state is not finite or has left
        the world (free_bodies.py), before it is stepped again (a material held by a suction
        cup is released first); each is in ``take_lost()``. ``pose=False``: velocities only
        (after every step)."""
        taken = False
        quick = not pose
        for m in list(self.materials):
            if quick and moving_within_reason(self._p, m.body):
                continue
            problem = base_problem(self._p, m.body, pose)
            if problem:
                for suction in self.suctions.values():
                    if suction.held is m:
                        suction.release(self.source)
                assert self.source is not None
                self.source.remove(m)
                self._lost.append(Lost(m.name or f'material_{m.index}',
                                       f'taken out of the world: {problem}'))
                taken = True
        for body, (name, forget) in list(self._guests.items()):
            if quick and moving_within_reason(self._p, body):
                continue
            problem = base_problem(self._p, body, pose)
            if problem:
                del self._guests[body]
                self._p.removeBody(body)
                forget()
                self._lost.append(Lost(name, f'taken out of the world: {problem}'))
                taken = True
        if taken:
            for name in self.repair_static():
                self._lost.append(Lost(name, 'put back where it belongs: its pose was not '
                                             'finite'))

    def take_lost(self) -> List[Lost]:
        """The bodies taken out of the world since the last call (and static bodies put back)."""
        lost, self._lost = self._lost, []
        return lost

    def repair_static(self) -> List[str]:
        """Put back every static body whose pose is no longer finite; their names."""
        repaired = []
        for body, (pos, orn) in self._static_poses.items():
            now_pos, now_orn = self._p.getBasePositionAndOrientation(body)
            if not math.isfinite(sum(now_pos) + sum(now_orn)):
                self._p.resetBasePositionAndOrientation(body, pos, orn)
                repaired.append(self.body_name(body))
        return repaired

    def reset(self) -> None:
        """Put every robot back at its start pose, at rest, and start the materials' scenario
        again (same seed). Simulated time keeps running."""
        for suction in self.suctions.values():
            suction.reset()
        for robot in self.robots.values():
            robot.reset()
        if self.source is not None:
            self.source.restart()

    def render(self, camera: SimCamera,
               lighting: Optional[Dict[str, Any]] = None) -> np.ndarray:
        """Render an RGBA frame (height x width x 4, uint8) with the CPU renderer, as the
        camera gives it: with the world's camera perturbations (noise, colour, blur), if any.
        ``lighting``: as :meth:`render_ideal`."""
        frame = self.render_ideal(camera, lighting)
        c = self.config.perturbations.camera
        if not (c.pixel_noise > 0.0 or c.brightness > 0.0 or c.white_balance > 0.0
                or c.blur > 0.0):
            return frame
        name = camera.config.name
        noise = (self.draws.frame_noise(name, self.sim_time_ns, (*frame.shape[:2], 3))
                 if c.pixel_noise > 0.0 else None)
        return perturb_frame(frame, self.draws.camera_gains(name), noise, c.blur)

    def render_ideal(self, camera: SimCamera,
                     lighting: Optional[Dict[str, Any]] = None) -> np.ndarray:
        """Render an RGBA frame (height x width x 4, uint8) with the CPU renderer: the scene
        itself, no camera perturbation.

        ``lighting``: getCameraImage's light arguments (lightDirection, lightColor,
        lightAmbientCoeff, lightDiffuseCoeff, lightSpecularCoeff), to vary the lighting.

        A fixed camera's frames in the default light are drawn without the static bodies, over
        an image of them drawn once (see sim_bridge.backdrop): the same image, bit for bit, for
        the cost of the pixels the moving bodies cover (the belt camera's frame: 15 ms drawn
        whole, 6 ms with the floor alone filled in, 1.5 ms now).
        """
        backdrop = None
        # PyBullet keeps the light arguments of the last frame that gave any for the frames
        # after it: once a frame was lit otherwise, the default light is unknown here.
        self._relit = self._relit or bool(lighting)
        if camera.robot is None and self.backdrops and not self._relit:
            key = camera.config.name
            if key not in self._backdrops:
                self._backdrops[key] = self._measure_backdrop(camera)
            backdrop = self._backdrops[key]
        if backdrop is None or self._static_visuals is None:
            return self._render(self._p, camera, lighting)[0]
        self._show_static(False)
        try:
            rgba, depth = self._render(self._p, camera, lighting)
        finally:
            self._show_static(True)
        return backdrop.fill(rgba, depth)

    @staticmethod
    def _render(client: BulletClient, camera: SimCamera, lighting: Optional[Dict[str, Any]]
                ) -> Tuple[np.ndarray, np.ndarray]:
        c = camera.config
        _, _, rgba, depth, _ = client.getCameraImage(
            c.width, c.height, camera.view_matrix(), camera.projection, shadow=0,
            renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK,
            **(lighting or {}))
        return (np.asarray(rgba, dtype=np.uint8).reshape(c.height, c.width, 4),
                np.asarray(depth, dtype=np.float32).reshape(c.height, c.width))

    def _show_static(self, shown: bool) -> None:
        for v in self._static_visuals or ():
            self._p.changeVisualShape(v.body, v.link, rgbaColor=v.rgba if shown else v.hidden())

    def _measure_backdrop(self, camera: SimCamera) -> Optional[StaticBackdrop]:
        """The static scene as this fixed camera sees it in the default light, drawn alone in
        a client of its own; None (draw every frame whole) if it cannot be drawn again alike."""
        if self._static_visuals is None:
            return None
        return StaticBackdrop.measure(self._static_visuals,
                                      lambda client: self._render(client, camera, None))

    def body_name(self, body: int, link: int = -1) -> str:
        """What a body of the world is, for messages: 'the floor', 'youbot's arm_link_5', ..."""
        if body == self.floor:
            return 'the floor'
        if body in self._obstacle_names:
            return self._obstacle_names[body]
        if self.conveyor is not None and body in (self.conveyor.body,
                                                  getattr(self.conveyor, 'stop_body', None)):
            return 'the conveyor'
        for name, robot in self.robots.items():
            if body == robot.body:
                return f"{name}'s {robot.link_name(link)}"
        for m in self.materials:
            if body == m.body:
                return f'material {m.index} ({m.color})'
        return f'body {body}'

    def contacts_of(self, group: 'JointGroup') -> List[str]:
        """What the links a joint group moves touch: ['gripper_finger_link_l on the floor']."""
        robot = group.robot
        found = []
        for c in self._p.getContactPoints(bodyA=robot.body):
            if c[3] in group.moved_links and (c[2], c[4]) != (robot.body, c[3]):
                text = f'{robot.link_name(c[3])} on {self.body_name(c[2], c[4])}'
                if text not in found:
                    found.append(text)
        return found

    def close(self) -> None:
        try:
            self._p.disconnect()
        except pybullet.error:
            pass

    def _build_floor(self, size: float) -> None:
        self.floor = build_floor(self._p, size)

    def _add_obstacle(self, obstacle: Any) -> None:
        p = self._p
        s = obstacle.size
        if obstacle.shape == 'box':
            kwargs = {'halfExtents': [v / 2 for v in s]}
            col = p.createCollisionShape(pybullet.GEOM_BOX, **kwargs)
            vis = p.createVisualShape(pybullet.GEOM_BOX, rgbaColor=obstacle.color, **kwargs)
        elif obstacle.shape == 'cylinder':
            col = p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=s[0], height=s[1])
            vis = p.createVisualShape(pybullet.GEOM_CYLINDER, radius=s[0], length=s[1],
                                      rgbaColor=obstacle.color)
        else:
            col = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=s[0])
            vis = p.createVisualShape(pybullet.GEOM_SPHERE, radius=s[0], rgbaColor=obstacle.color)
        if not obstacle.collision:
            col = -1
        body = p.createMultiBody(0.0, col, vis, basePosition=obstacle.position,
                                 baseOrientation=p.getQuaternionFromEuler((0.0, 0.0,
                                                                          obstacle.yaw)))
        self.obstacles[body] = obstacle
        self._obstacle_names[body] = (f'the {obstacle.name}' if obstacle.name else
                                      f'an obstacle ({obstacle.shape})')
