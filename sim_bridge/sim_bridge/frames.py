"""The world's TF tree, from the simulation's ground truth (no rclpy): what sim_node publishes
on /tf and /tf_static.

REP-105 names, with each robot's frame prefix (``youbot/``, ``zu12/``) so that no two robots
share a frame:

- ``world`` -> ``<prefix>odom``: a mobile robot's start pose (static);
  ``world`` -> ``<prefix>base_link``: a robot with a fixed base (static);
- ``<prefix>odom`` -> ``<prefix>base_link``: where a mobile robot's base is (moving);
- a URDF joint's parent link -> child link: moving for a movable joint, static for a fixed one
  (a robot-mounted camera's optical frame is such a link);
- ``world`` -> a fixed camera's optical frame (static; z forward, x right, y down);
- ``<prefix>base_link`` -> ``<prefix>laser``: a base's laser scanner (static).

Transforms between link frames are taken from PyBullet's link frames (URDF frames, not the
inertial frames PyBullet reports for bodies and uses for joint origins), and composed in double
precision here (PyBullet's multiplyTransforms and invertTransform work in single precision).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pybullet

from controllers.transforms import matrix_to_quaternion, quaternion_to_matrix
from sim_bridge.world import SimCamera, SimRobot, SimWorld
from world_description.camera_geometry import look_at_rotation

WORLD_FRAME = 'world'

Vec3 = Tuple[float, float, float]
Quat = Tuple[float, float, float, float]      # x, y, z, w


@dataclass(frozen=True)
class FrameTransform:
    """The pose of ``child`` in ``parent``."""

    parent: str
    child: str
    translation: Vec3
    rotation: Quat


@dataclass(frozen=True)
class _Joint:
    parent: int           # PyBullet link index of the parent link (-1: the base)
    child: int            # PyBullet link index of the child link
    parent_frame: str
    child_frame: str


class RobotFrames:
    """One robot's frames: its anchor in the world, its base in odom, its links."""

    def __init__(self, robot: SimRobot) -> None:
        self.robot = robot
        prefix = robot.config.frame_prefix
        names = {index: prefix + name for name, index in robot.link_index.items()}
        self.base_frame = names[-1]
        self.odom_frame = prefix + 'odom'
        self.mobile = not robot.config.fixed_base
        client, body = robot.client, robot.body
        self._moving: List[_Joint] = []
        self._fixed: List[_Joint] = []
        for j in range(client.getNumJoints(body)):
            info = client.getJointInfo(body, j)
            joint = _Joint(parent=info[16], child=j, parent_frame=names[info[16]],
                           child_frame=names[j])
            (self._fixed if info[2] == pybullet.JOINT_FIXED else self._moving).append(joint)
        self._start = robot.start_pose

    @property
    def link_frames(self) -> List[str]:
        return [self.base_frame] + [j.child_frame for j in self._moving + self._fixed]

    def anchor(self) -> FrameTransform:
        """world -> odom (the start pose) for a mobile robot, world -> base_link otherwise."""
        (x, y, z), rotation = self._start
        return FrameTransform(WORLD_FRAME, self.odom_frame if self.mobile else self.base_frame,
                              (x, y, z), rotation)

    def base(self) -> Optional[FrameTransform]:
        """odom -> base_link now, for a mobile robot."""
        if not self.mobile:
            return None
        return _relative(self.odom_frame, self.base_frame, self._start,
                         self.robot.base_link_world())

    def moving_links(self) -> List[FrameTransform]:
        """parent -> child of every movable joint, now."""
        return self._relative(self._moving)

    def fixed_links(self) -> List[FrameTransform]:
        """parent -> child of every fixed joint (constant)."""
        return self._relative(self._fixed)

    def _relative(self, joints: Sequence[_Joint]) -> List[FrameTransform]:
        if not joints:
            return []
        client, body = self.robot.client, self.robot.body
        indices = sorted({j.child for j in joints} | {j.parent for j in joints} - {-1})
        frames: Dict[int, Tuple[Sequence[float], Tuple[float, float, float, float]]] = {
            -1: self.robot.base_link_world()}
        for index, state in zip(indices, client.getLinkStates(
                body, indices, computeForwardKinematics=True)):
            frames[index] = (state[4], state[5])
        return [_relative(j.parent_frame, j.child_frame, frames[j.parent], frames[j.child])
                for j in joints]


def _relative(parent_frame: str, child_frame: str, parent: Tuple[Sequence[float], Quat],
              child: Tuple[Sequence[float], Quat]) -> FrameTransform:
    """The pose of ``child`` in ``parent``, both given as (position, quaternion) in the
    world."""
    parent_rot = quaternion_to_matrix(parent[1])
    rot = parent_rot.T @ quaternion_to_matrix(child[1])
    pos = parent_rot.T @ (np.asarray(child[0], float) - np.asarray(parent[0], float))
    return FrameTransform(parent_frame, child_frame, (float(pos[0]), float(pos[1]),
                                                      float(pos[2])), matrix_to_quaternion(rot))


def camera_anchor(camera: SimCamera) -> Optional[FrameTransform]:
    """world -> a fixed camera's optical frame; None for a camera on a robot (its optical
    frame is a link of the robot's tree)."""
    c = camera.config
    if camera.robot is not None or c.position is None or c.look_at is None:
        return None
    x, y, z = c.position
    return FrameTransform(WORLD_FRAME, c.frame_id, (float(x), float(y), float(z)),
                          matrix_to_quaternion(look_at_rotation(c.position, c.look_at)))


def laser_mount(robot: SimRobot) -> FrameTransform:
    """``<prefix>base_link`` -> ``<prefix>laser``: where a robot's laser scanner sits."""
    c, prefix = robot.config.laser, robot.config.frame_prefix
    assert c is not None
    half = 0.5 * c.yaw
    return FrameTransform(prefix + 'base_link', prefix + 'laser', (c.x, c.y, c.z),
                          (0.0, 0.0, float(np.sin(half)), float(np.cos(half))))


class WorldFrames:
    """Every robot's frames and the fixed cameras', for /tf and /tf_static."""

    def __init__(self, world: SimWorld) -> None:
        self.robots = {name: RobotFrames(robot) for name, robot in world.robots.items()}
        self._cameras = [t for t in (camera_anchor(c) for c in world.cameras) if t is not None]
        self._lasers = [laser_mount(robot) for robot in world.robots.values()
                        if robot.config.laser is not None]

    def static(self) -> List[FrameTransform]:
        """Everything that never moves: what /tf_static carries."""
        out = list(self._cameras) + self._lasers
        for frames in self.robots.values():
            out.append(frames.anchor())
            out.extend(frames.fixed_links())
        return out

    def moving(self, robot: str, links: bool = True) -> List[FrameTransform]:
        """What /tf carries for ``robot`` now: its base in odom, and (``links``) its movable
        joints' transforms."""
        frames = self.robots[robot]
        base = frames.base()
        return ([base] if base is not None else []) + (frames.moving_links() if links else [])
