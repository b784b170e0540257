"""A mobile base's odometry in the cell's frame (no ROS). Its odom frame is its start pose in the
cell (REP-105; no tf2 here): a pose there is turned into the cell's frame, and its twist, which
odometry gives in the child (base) frame, into the cell's axes (what the path follower wants)."""
from __future__ import annotations

import math
from typing import Tuple

from controllers.bezier import Pose2D

Pose = Tuple[float, float, float]


def odometry_in_cell(home: Pose2D, x: float, y: float, yaw: float, vx: float, vy: float,
                     wz: float) -> Tuple[Pose, Pose]:
    """((x, y, yaw) in the cell, (vx, vy, wz) along the cell's axes) of a base at (x, y, yaw)
    in its odom frame, moving at (vx, vy) in its own frame and turning at ``wz``; ``home``:
    the odom frame's pose in the cell."""
    hx, hy, hyaw = home
    c, s = math.cos(hyaw), math.sin(hyaw)
    pose = (hx + c * x - s * y, hy + s * x + c * y, hyaw + yaw)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose, (c * vx - s * vy, s * vx + c * vy, wz)
