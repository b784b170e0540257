"""One robot of the world: its URDF body in PyBullet, its joints and links, its base frame, its
drive and joint-group controllers (actuation.py), the brake at its joints' speed limits
(joint_speed.py), and its sensors: what its encoders and odometry report, perturbed or not
(sensors.py)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, FrozenSet, List, Optional, Sequence, Set, Tuple, Union, cast

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from sim_bridge.actuation import DiffDrive, JointGroup, MecanumDrive
from sim_bridge.errors import WorldError
from sim_bridge.free_bodies import base_problem
from sim_bridge.joint_speed import SpeedLimiter
from sim_bridge.sensors import RobotSensors, Transform
from world_description.world_config import DiffDriveConfig, MecanumConfig, RobotConfig

# Inertias as written in the URDF; true cylinders, because the convex hull PyBullet otherwise
# makes of a URDF cylinder rolls on its collision margin (a 2 % larger effective wheel radius).
URDF_FLAGS = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_USE_IMPLICIT_CYLINDER

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
        # What its encoders and odometry report, with their errors (sensors.py).
        self.sensors = RobotSensors(self)
        self._load()

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
        self.inertial_offset: Transform = (info[3], info[4])
        self.joint_index: Dict[str, int] = {}
        self.root_link = str(client.getBodyInfo(self.body)[0].decode())
        self.link_index: Dict[str, int] = {self.root_link: -1}
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
        self.sensors.joints_loaded()
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
            [self._joint_limits[n][2] for n in self._joint_names], self.sensors.report_scales,
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
            return self.root_link
        return str(self.client.getJointInfo(self.body, link)[12].decode())

    def links_moved_by(self, joints: Sequence[int]) -> FrozenSet[int]:
        """The links (PyBullet link indices) downstream of any of these joints."""
        moved = set(joints)
        for link in range(self.client.getNumJoints(self.body)):   # (parents come first)
            if self.client.getJointInfo(self.body, link)[16] in moved:
                moved.add(link)
        return frozenset(moved)

    def base_link_world(self) -> Transform:
        com_pos, com_orn = self.client.getBasePositionAndOrientation(self.body)
        inv_pos, inv_orn = self.client.invertTransform(*self.inertial_offset)
        return cast(Transform, self.client.multiplyTransforms(com_pos, com_orn, inv_pos,
                                                              inv_orn))

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
        base_pos, base_rot = self.link_world_pose(self.root_link)
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
                self.body, j, self._initial.get(j, 0.0) + self.sensors.encoder_offset(j), 0.0)
        if self.drive is not None:
            self.drive.command(0.0, 0.0, 0.0)
        self.sensors.restart_odometry()
        for group in self.controllers.values():
            group.hold_current()

    @property
    def start_pose(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
        """base_link's pose in the world at start: the odom frame of a mobile robot."""
        return self._start_pos, self._start_orn

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
            self._start_pos, self._start_orn, *self.inertial_offset))
