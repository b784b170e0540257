"""Camera geometry of the world file's cameras (no ROS, no renderer): the pinhole model of the
images the simulator renders, and a camera's pose from where it looks."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def k(self) -> Tuple[float, ...]:
        """Row-major 3x3 camera matrix (sensor_msgs/CameraInfo.k)."""
        return (self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)

    @property
    def p(self) -> Tuple[float, ...]:
        """Row-major 3x4 projection matrix of a monocular camera (CameraInfo.p)."""
        return (self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0)

    def project(self, point_optical: Sequence[float]) -> Tuple[float, float]:
        """Pixel (u, v) of a point in the optical frame; pixel centres are integers (ROS)."""
        x, y, z = point_optical
        return self.fx * x / z + self.cx, self.fy * y / z + self.cy


def intrinsics_from_fov(width: int, height: int, vertical_fov_deg: float) -> Intrinsics:
    """Intrinsics of the images PyBullet's TinyRenderer draws with computeProjectionMatrixFOV.

    OpenGL maps the vertical field of view onto the image height with square pixels, so
    fx = fy = (height/2) / tan(fov/2). The principal point is where TinyRenderer actually puts
    the optical axis, measured with rendered markers (tests/unit/test_camera_model.py): it
    samples pixel column i at x = i and, rows being flipped, row r at y = r + 1, so with ROS's
    integer pixel centres cx = width/2 and cy = height/2 - 1 (not the (n-1)/2 of an ideal
    pixel-centre sampler).
    """
    fy = 0.5 * height / math.tan(math.radians(vertical_fov_deg) / 2.0)
    return Intrinsics(width, height, fy, fy, width / 2.0, height / 2.0 - 1.0)


def look_at_rotation(position: Sequence[float], target: Sequence[float]) -> np.ndarray:
    """Rotation of an optical frame at ``position`` looking at ``target`` with world z up."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack((x, y, z))
