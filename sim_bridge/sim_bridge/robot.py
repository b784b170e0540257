"""One robot of the world: its URDF body in PyBullet, its joints and links, its base frame and
odometry, its drive and joint-group controllers (actuation.py), the brake at its joints' speed
limits (joint_speed.py), and the perturbations of its encoders and odometry."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, FrozenSet, List, Optional, Sequence, Set, Tuple, Union, cast

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.transforms import yaw_from_quaternion
from sim_bridge.actuation import DiffDrive, JointGroup, MecanumDrive
from sim_bridge.errors import WorldError
from sim_bridge.free_bodies import base_problem
from sim_bridge.joint_speed import SpeedLimiter
from world_description.world_config import DiffDriveConfig, MecanumConfig, RobotConfig

# Inertias as written in the URDF; true cylinders, because the convex hull PyBullet otherwise
# makes of a URDF cylinder rolls on its collision margin (a 2 % larger effective wheel radius).
URDF_FLAGS = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_USE_IMPLICIT_CYLINDER

# A pose as PyBullet gives it: position, quaternion (x, y, z, w).
Transform = Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]


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
        self.drive: Optional[Union[DiffDrive, MecanumDrive]] = None
        if isinstance(config.drive, DiffDriveConfig):
            self.drive = DiffDrive(self, config.drive)
        elif isinstance(config.drive, MecanumConfig):
            self.drive = MecanumDrive(self, config.drive)
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
