"""Pinhole camera model matching PyBullet's OpenGL projection, and a reusable image buffer."""
from __future__ import annotations

import array
import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

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


def projection_matrix(width: int, height: int, vertical_fov_deg: float, near: float,
                      far: float) -> Tuple[float, ...]:
    """The column-major OpenGL matrix PyBullet's computeProjectionMatrixFOV returns."""
    f = 1.0 / math.tan(math.radians(vertical_fov_deg) / 2.0)
    aspect = width / height
    return (f / aspect, 0.0, 0.0, 0.0,
            0.0, f, 0.0, 0.0,
            0.0, 0.0, (far + near) / (near - far), -1.0,
            0.0, 0.0, 2.0 * far * near / (near - far), 0.0)


def view_matrix_from_optical(position: Sequence[float], rotation: np.ndarray
                             ) -> Tuple[float, ...]:
    """Column-major OpenGL view matrix of a camera whose optical frame has this world pose.

    Optical frame: z forward, x right, y down. OpenGL's camera looks along -z with y up, so its
    axes are (x, -y, -z) of the optical frame.
    """
    r_gl = np.column_stack((rotation[:, 0], -rotation[:, 1], -rotation[:, 2]))
    view = np.eye(4)
    view[:3, :3] = r_gl.T
    view[:3, 3] = -r_gl.T @ np.asarray(position, dtype=float)
    return tuple(view.T.ravel())


def look_at_rotation(position: Sequence[float], target: Sequence[float]) -> np.ndarray:
    """Rotation of an optical frame at ``position`` looking at ``target`` with world z up."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack((x, y, z))


class ImageBuffer:
    """Writes rgb8 frames into one byte array in place, without per-frame allocation.

    rclpy copies a numpy array into Image.data element by element (about 140 ms at 640x480),
    and its setter copies whatever it is given into a new ``array.array``. So the buffer must be
    the array that the message already owns (``msg.data``); frames are copied into a numpy view
    of it, a plain memcpy.
    """

    def __init__(self, width: int, height: int, data: Optional[array.array] = None) -> None:
        self.width, self.height = width, height
        size = width * height * 3
        self.data = data if data is not None else array.array('B', bytes(size))
        if not isinstance(self.data, array.array) or self.data.typecode != 'B' \
                or len(self.data) != size:
            raise ValueError(f'need an array.array of {size} unsigned bytes')
        self._view = np.frombuffer(self.data, dtype=np.uint8).reshape(height, width, 3)

    def fill_from_rgba(self, rgba: np.ndarray) -> array.array:
        rgba = np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.width, 4)
        self._view[...] = rgba[:, :, :3]
        return self.data
