"""The PyBullet world: loads a WorldConfig, steps physics, drives bases, renders cameras."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.diff_drive import DiffDriveGeometry, wheel_speeds
from sim_bridge.camera import (intrinsics_from_fov, look_at_rotation, projection_matrix,
                               view_matrix_from_optical)
from sim_bridge.world_config import CameraConfig, RobotConfig, WorldConfig

FLOOR_COLOR = (0.82, 0.80, 0.76, 1.0)
# Inertias as written in the URDF; true cylinders, because the convex hull PyBullet otherwise
# makes of a URDF cylinder rolls on its collision margin (a 2 % larger effective wheel radius).
URDF_FLAGS = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_USE_IMPLICIT_CYLINDER


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


def resolve_resource(uri: str, base_dir: Optional[Path] = None) -> Path:
    """Resolve ``package://pkg/rel``, ``file://`` or a path (relative to the world file)."""
    if uri.startswith('package://'):
        package, _, rel = uri[len('package://'):].partition('/')
        share = _package_share(package)
        return share / rel
    if uri.startswith('file://'):
        uri = uri[len('file://'):]
    path = Path(uri)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    return path


def _package_share(package: str) -> Path:
    try:
        from ament_index_python.packages import (PackageNotFoundError,
                                                 get_package_share_directory)
        try:
            return Path(get_package_share_directory(package))
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            pass
    except ImportError:
        pass
    if package == 'robot_description':
        from robot_description import share_directory
        return share_directory()
    raise WorldError(f'package "{package}" not found in the ament index '
                     '(is the workspace sourced?)')


class SimRobot:
    """One URDF body: its joints, its base frame, and its drive."""

    def __init__(self, client: BulletClient, config: RobotConfig, urdf: Path) -> None:
        self.config = config
        self._p = client
        if not urdf.is_file():
            raise WorldError(f'robot "{config.name}": URDF {urdf} does not exist')
        pose = config.pose
        self._start_pos = (pose.x, pose.y, pose.z)
        self._start_orn = tuple(client.getQuaternionFromEuler((0.0, 0.0, pose.yaw)))
        try:
            self.body = client.loadURDF(str(urdf), self._start_pos, self._start_orn,
                                        flags=URDF_FLAGS)
        except pybullet.error as exc:
            raise WorldError(
                f'robot "{config.name}": PyBullet cannot load {urdf}: {exc}') from None
        # PyBullet reports the base's inertial frame; keep its offset from base_link.
        info = client.getDynamicsInfo(self.body, -1)
        self._inertial_pos, self._inertial_orn = info[3], info[4]
        self.joint_index: Dict[str, int] = {}
        self.link_index: Dict[str, int] = {client.getBodyInfo(self.body)[0].decode(): -1}
        self.movable: List[int] = []
        self._joint_names: List[str] = []
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            name, jtype = info[1].decode(), info[2]
            self.joint_index[name] = j
            self.link_index[info[12].decode()] = j
            if jtype != pybullet.JOINT_FIXED:
                self.movable.append(j)
                self._joint_names.append(name)
                # Free joints by default; PyBullet otherwise brakes each one with a motor.
                client.setJointMotorControl2(self.body, j, pybullet.VELOCITY_CONTROL, force=0.0)
        self._drive_joints: Tuple[int, int] = (-1, -1)
        self.geometry: Optional[DiffDriveGeometry] = None
        if config.drive is not None:
            d = config.drive
            for joint in (d.left_wheel_joint, d.right_wheel_joint):
                if joint not in self.joint_index or self.joint_index[joint] not in self.movable:
                    raise WorldError(f'robot "{config.name}": drive joint "{joint}" is not a '
                                     f'movable joint of {urdf.name}')
            self._drive_joints = (self.joint_index[d.left_wheel_joint],
                                  self.joint_index[d.right_wheel_joint])
            self.geometry = DiffDriveGeometry(d.wheel_radius, d.wheel_separation)
        self.wheel_targets = (0.0, 0.0)
        if self.geometry is not None:
            self.set_body_twist(0.0, 0.0)

    @property
    def joint_names(self) -> List[str]:
        return list(self._joint_names)

    def set_body_twist(self, v: float, w: float) -> Tuple[float, float]:
        """Command the wheel velocity motors for body twist (v, w); returns (left, right)."""
        if self.geometry is None:
            raise WorldError(f'robot "{self.config.name}" has no drive')
        targets = wheel_speeds(v, w, self.geometry)
        effort = self.config.drive.wheel_effort
        for joint, target in zip(self._drive_joints, targets):
            self._p.setJointMotorControl2(self.body, joint, pybullet.VELOCITY_CONTROL,
                                          targetVelocity=target, force=effort)
        self.wheel_targets = targets
        return targets

    def joint_states(self) -> JointStates:
        states = self._p.getJointStates(self.body, self.movable)
        return JointStates(self.joint_names, [s[0] for s in states], [s[1] for s in states],
                           [s[3] for s in states])

    def base_link_world(self) -> Tuple[tuple, tuple]:
        com_pos, com_orn = self._p.getBasePositionAndOrientation(self.body)
        inv_pos, inv_orn = self._p.invertTransform(self._inertial_pos, self._inertial_orn)
        return self._p.multiplyTransforms(com_pos, com_orn, inv_pos, inv_orn)

    def base_state(self) -> BaseState:
        pos, orn = self.base_link_world()
        com_pos, _ = self._p.getBasePositionAndOrientation(self.body)
        v_com, omega = self._p.getBaseVelocity(self.body)
        # Velocity of the base_link origin, not of the centre of mass.
        v_link = np.asarray(v_com) + np.cross(omega, np.subtract(pos, com_pos))
        rot = np.array(self._p.getMatrixFromQuaternion(orn)).reshape(3, 3)
        # Pose relative to the start pose, which is the odom frame's origin.
        inv_pos, inv_orn = self._p.invertTransform(self._start_pos, self._start_orn)
        odom_pos, odom_orn = self._p.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        return BaseState(tuple(odom_pos), tuple(odom_orn), tuple(rot.T @ v_link),
                         tuple(rot.T @ np.asarray(omega)))

    def link_world_pose(self, link: str) -> Tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of a link frame (URDF frame, not inertial)."""
        if link not in self.link_index:
            raise WorldError(f'robot "{self.config.name}" has no link "{link}"')
        index = self.link_index[link]
        if index == -1:
            pos, orn = self.base_link_world()
        else:
            state = self._p.getLinkState(self.body, index, computeForwardKinematics=True)
            pos, orn = state[4], state[5]
        return np.asarray(pos), np.array(self._p.getMatrixFromQuaternion(orn)).reshape(3, 3)

    def reset(self) -> None:
        self._p.resetBasePositionAndOrientation(self.body, *self._start_com())
        self._p.resetBaseVelocity(self.body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        for j in self.movable:
            self._p.resetJointState(self.body, j, 0.0, 0.0)
        if self.geometry is not None:
            self.set_body_twist(0.0, 0.0)

    def _start_com(self) -> Tuple[tuple, tuple]:
        return self._p.multiplyTransforms(self._start_pos, self._start_orn,
                                          self._inertial_pos, self._inertial_orn)


class SimCamera:
    def __init__(self, config: CameraConfig, robot: Optional[SimRobot]) -> None:
        self.config = config
        self.robot = robot
        self.intrinsics = intrinsics_from_fov(config.width, config.height,
                                              config.vertical_fov_deg)
        self._projection = projection_matrix(config.width, config.height,
                                             config.vertical_fov_deg, config.near, config.far)
        if robot is None:
            self._fixed_view = view_matrix_from_optical(
                config.position, look_at_rotation(config.position, config.look_at))
        elif config.link not in robot.link_index:
            raise WorldError(f'camera "{config.name}": robot "{robot.config.name}" has no link '
                             f'"{config.link}"')

    def view_matrix(self) -> Tuple[float, ...]:
        if self.robot is None:
            return self._fixed_view
        pos, rot = self.robot.link_world_pose(self.config.link)
        return view_matrix_from_optical(pos, rot)

    @property
    def projection(self) -> Tuple[float, ...]:
        return self._projection


class SimWorld:
    """Owns one PyBullet client. Every physics step goes through :meth:`step`."""

    def __init__(self, config: WorldConfig, time_step: float = 1.0 / 240.0,
                 gui: bool = False) -> None:
        if not (0.0 < time_step <= 0.1):
            raise ValueError(f'time_step must be within (0, 0.1] s, got {time_step}')
        self.config = config
        self.time_step = time_step
        self.step_count = 0
        self._p = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        p = self._p
        p.setTimeStep(time_step)
        p.setGravity(0.0, 0.0, config.gravity)
        self._build_floor(config.floor_size)
        for obstacle in config.obstacles:
            self._add_obstacle(obstacle)
        base_dir = Path(config.source).parent if config.source else None
        self.robots: Dict[str, SimRobot] = {}
        for rc in config.robots:
            self.robots[rc.name] = SimRobot(p, rc, resolve_resource(rc.urdf, base_dir))
        self.cameras: List[SimCamera] = [
            SimCamera(cc, self.robots[cc.robot] if cc.robot else None) for cc in config.cameras]

    @property
    def sim_time(self) -> float:
        return self.step_count * self.time_step

    @property
    def sim_time_ns(self) -> int:
        # Integer nanoseconds so that lock-step time is exact after any number of steps.
        return self.step_count * round(self.time_step * 1e9)

    def step(self) -> None:
        self._p.stepSimulation()
        self.step_count += 1

    def reset(self) -> None:
        """Put every robot back at its start pose, at rest. Simulated time keeps running."""
        for robot in self.robots.values():
            robot.reset()

    def render(self, camera: SimCamera) -> np.ndarray:
        """Render an RGBA frame (height x width x 4, uint8) with the CPU renderer."""
        c = camera.config
        _, _, rgba, _, _ = self._p.getCameraImage(
            c.width, c.height, camera.view_matrix(), camera.projection, shadow=0,
            renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK)
        return np.asarray(rgba, dtype=np.uint8).reshape(c.height, c.width, 4)

    def close(self) -> None:
        try:
            self._p.disconnect()
        except pybullet.error:
            pass

    def _build_floor(self, size: float) -> None:
        # Infinite collision plane, but only a plain finite patch is drawn: PyBullet's large
        # textured plane is the biggest cost of a CPU-rendered frame.
        p = self._p
        plane = p.createCollisionShape(pybullet.GEOM_PLANE)
        visual = p.createVisualShape(pybullet.GEOM_BOX, halfExtents=(size / 2, size / 2, 0.0005),
                                     rgbaColor=FLOOR_COLOR,
                                     visualFramePosition=(0.0, 0.0, -0.0005))
        self.floor = p.createMultiBody(0.0, plane, visual)
        p.changeDynamics(self.floor, -1, lateralFriction=1.0)

    def _add_obstacle(self, obstacle) -> None:
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
        p.createMultiBody(0.0, col, vis, basePosition=obstacle.position,
                          baseOrientation=p.getQuaternionFromEuler((0.0, 0.0, obstacle.yaw)))


def yaw_from_quaternion(q: Tuple[float, float, float, float]) -> float:
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
