"""What a robot's sensors report (no ROS): its joint encoders and its odometry, with the errors
a perturbed world gives them (an offset per joint, a scale per odometry axis) and the reporting
scale of a virtual omni-wheel. ``RobotSensors`` is the only writer of those errors; its
``*_as_reported`` undo them, to pose a robot where a recording says it was."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Protocol, Sequence, Tuple

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from controllers.transforms import yaw_from_quaternion

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


class SensedBody(Protocol):
    """What the sensors read of the body they are on (robot.py's SimRobot)."""

    client: BulletClient
    body: int
    movable: List[int]
    joint_index: Dict[str, int]

    @property
    def start_pose(self) -> Transform: ...

    @property
    def inertial_offset(self) -> Transform: ...      # the base's centre of mass in base_link

    @property
    def joint_names(self) -> List[str]: ...

    def base_link_world(self) -> Transform: ...


class RobotSensors:
    def __init__(self, robot: SensedBody) -> None:
        self._robot = robot
        # Each joint's offset [rad] between where it is and where its encoder says (by PyBullet
        # index), and the factors the odometry gets its x, y and yaw motion wrong by.
        self._encoder_offset: Dict[int, float] = {}
        self.odometry_scale = (1.0, 1.0, 1.0)
        # The base's turn since its start, unwrapped, and its yaw when last read (odom frame).
        self._turned = self._yaw = 0.0
        # Reported angle per movable joint = scale * PyBullet joint angle (virtual omni-wheels).
        self._report_scale = np.ones(0)

    def joints_loaded(self) -> None:
        """The body was (re)loaded: each joint is reported as it turns, until a drive says
        otherwise (``scale_reported_angle``)."""
        self._report_scale = np.ones(len(self._robot.movable))
        self.restart_odometry()

    def restart_odometry(self) -> None:
        """The base is back at its start pose: its odometry starts again from there."""
        self._turned = self._yaw = 0.0

    @property
    def report_scales(self) -> List[float]:
        return [float(k) for k in self._report_scale]

    def set_perturbations(self, offsets: Dict[int, float],
                          odometry_scale: Tuple[float, float, float]) -> None:
        """A mis-calibrated robot: each joint in ``offsets`` (PyBullet index) sits that far
        [rad] from where its encoder (the joint states, its controller) says, and its odometry
        reports its motion times ``odometry_scale`` (x, y, yaw)."""
        self._encoder_offset = {j: float(v) for j, v in offsets.items() if v != 0.0}
        self.odometry_scale = odometry_scale

    def encoder_offset(self, joint: int) -> float:
        """How far [rad] a joint (PyBullet index) is from where its encoder says."""
        return self._encoder_offset.get(joint, 0.0)

    def scale_reported_angle(self, joint: int, scale: float) -> None:
        """Report this movable joint's angle and speed times ``scale`` (a virtual omni-wheel
        turns 1/sqrt(2) as fast as the Mecanum wheel it stands for)."""
        self._report_scale[self._robot.movable.index(joint)] = scale

    def joint_states(self) -> JointStates:
        r = self._robot
        states = r.client.getJointStates(r.body, r.movable)
        scale = self._report_scale
        off = [self.encoder_offset(j) for j in r.movable]
        # A virtual omni-wheel turns 1/sqrt(2) as fast with sqrt(2) times the torque (same power).
        return JointStates(r.joint_names, [s[0] * k - o for s, k, o in zip(states, scale, off)],
                           [s[1] * k for s, k in zip(states, scale)],
                           [s[3] / k for s, k in zip(states, scale)])

    def joint_positions(self, joints: Sequence[str]) -> np.ndarray:
        """Where the joints' encoders say they are."""
        r = self._robot
        index = [r.joint_index[j] for j in joints]
        states = r.client.getJointStates(r.body, index)
        return np.array([s[0] - self.encoder_offset(j) for s, j in zip(states, index)])

    def joint_velocities(self, joints: Sequence[str]) -> np.ndarray:
        r = self._robot
        states = r.client.getJointStates(r.body, [r.joint_index[j] for j in joints])
        return np.array([s[1] for s in states])

    def base_state(self) -> BaseState:
        """The odometry: base_link's pose in the odom frame and its twist, as reported."""
        r, p = self._robot, self._robot.client
        pos, orn = r.base_link_world()
        com_pos, _ = p.getBasePositionAndOrientation(r.body)
        v_com, omega = p.getBaseVelocity(r.body)
        # Velocity of the base_link origin, not of the centre of mass.
        v_link = np.asarray(v_com) + np.cross(omega, np.subtract(pos, com_pos))
        rot = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
        # Pose relative to the start pose, which is the odom frame's origin.
        inv_pos, inv_orn = p.invertTransform(*r.start_pose)
        odom_pos, odom_orn = p.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        linear, angular = rot.T @ v_link, rot.T @ np.asarray(omega)
        sx, sy, syaw = self.odometry_scale
        if (sx, sy, syaw) != (1.0, 1.0, 1.0):
            # Odometry that drifts: its pose and twist off by a scale per axis; its heading by
            # the scale of the turn since the start, unwrapped (read at least every half turn).
            # Scaled, the wrapped yaw jumped by 2 pi (syaw - 1) where the base crossed +-pi: a
            # base standing at a goal there read 0.09 rad off every other moment, and its
            # drive never settled (75 of 130 perturbed trials lost 14 s so at one stand).
            yaw = yaw_from_quaternion(odom_orn)
            self._turned += math.remainder(yaw - self._yaw, 2.0 * math.pi)
            self._yaw = yaw
            extra = p.getQuaternionFromEuler((0.0, 0.0, self._turned * (syaw - 1.0)))
            _, turned = p.multiplyTransforms((0.0, 0.0, 0.0), extra, (0.0, 0.0, 0.0), odom_orn)
            odom_pos, odom_orn = (odom_pos[0] * sx, odom_pos[1] * sy, odom_pos[2]), turned
            linear, angular = linear * (sx, sy, 1.0), angular * (1.0, 1.0, syaw)
        return BaseState(tuple(odom_pos), tuple(odom_orn), tuple(linear), tuple(angular))

    def pose_as_reported(self, names: Sequence[str], positions: Sequence[float]) -> None:
        """Put the joints where joint states that said ``positions`` found them (the inverse
        of :meth:`joint_states`: its encoder offsets and reporting scales undone); names it
        does not have are left out. To show a recorded moment, not to simulate on from it."""
        r = self._robot
        for name, reported in zip(names, positions):
            j = r.joint_index.get(name)
            if j is None or j not in r.movable or not math.isfinite(reported):
                continue
            scale = float(self._report_scale[r.movable.index(j)])
            r.client.resetJointState(r.body, j, (reported + self.encoder_offset(j)) / scale)

    def place_as_reported(self, position: Sequence[float],
                          orientation: Sequence[float]) -> None:
        """Put the base where odometry that said ``position``, ``orientation`` (x, y, z, w; in
        the odom frame) found it: the inverse of :meth:`base_state` (its scale errors undone).
        A pose that is not finite leaves the base where it is."""
        if not all(math.isfinite(v) for v in (*position, *orientation)):
            return
        r, p = self._robot, self._robot.client
        sx, sy, syaw = self.odometry_scale
        pos = (position[0] / sx, position[1] / sy, position[2])
        yaw = yaw_from_quaternion(orientation)
        undo = p.getQuaternionFromEuler((0.0, 0.0, yaw * (1.0 / syaw - 1.0)))
        _, orn = p.multiplyTransforms((0.0, 0.0, 0.0), undo, (0.0, 0.0, 0.0), orientation)
        world_pos, world_orn = p.multiplyTransforms(*r.start_pose, pos, orn)
        com = p.multiplyTransforms(world_pos, world_orn, *r.inertial_offset)
        p.resetBasePositionAndOrientation(r.body, *com)
