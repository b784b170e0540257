"""A camera of the world (``SimCamera``: fixed, or on a robot's link), PyBullet's OpenGL
matrices for it (its pinhole model is world_description.camera_geometry), and a reusable image
buffer."""
from __future__ import annotations

import array
import math
from typing import Optional, Tuple

import cv2
import numpy as np

from controllers.arrays import Vector
from controllers.transforms import rpy_matrix
from sim_bridge.errors import WorldError
from sim_bridge.robot import SimRobot
from world_description.camera_geometry import intrinsics_from_fov, look_at_rotation
from world_description.world_config import CameraConfig


def projection_matrix(width: int, height: int, vertical_fov_deg: float, near: float,
                      far: float) -> Tuple[float, ...]:
    """The column-major OpenGL matrix PyBullet's computeProjectionMatrixFOV returns."""
    f = 1.0 / math.tan(math.radians(vertical_fov_deg) / 2.0)
    aspect = width / height
    return (f / aspect, 0.0, 0.0, 0.0,
            0.0, f, 0.0, 0.0,
            0.0, 0.0, (far + near) / (near - far), -1.0,
            0.0, 0.0, 2.0 * far * near / (near - far), 0.0)


def view_matrix_from_optical(position: Vector, rotation: np.ndarray
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


def perturb_frame(rgba: np.ndarray, gains: np.ndarray, noise: Optional[np.ndarray],
                  blur: float) -> np.ndarray:
    """A frame as a real camera gives it: each colour channel times its gain (brightness and
    white balance), blurred (Gaussian, ``blur`` px), pixel noise added (levels, float32, one
    per pixel and channel); rounded and clipped to 0-255, alpha kept. A new array."""
    rgb = rgba[:, :, :3].astype(np.float32) * np.asarray(gains, dtype=np.float32)
    if blur > 0.0:
        rgb = np.asarray(cv2.GaussianBlur(rgb, (0, 0), blur), dtype=np.float32)
    if noise is not None:
        rgb += noise
    out = np.array(rgba, dtype=np.uint8, copy=True)
    out[:, :, :3] = np.clip(np.rint(rgb), 0.0, 255.0).astype(np.uint8)
    return out


class ImageBuffer:
    """Writes rgb8 frames into one byte array in place, without per-frame allocation.

    rclpy copies a numpy array into Image.data element by element (about 140 ms at 640x480),
    and its setter copies whatever it is given into a new ``array.array``. So the buffer must be
    the array that the message already owns (``msg.data``); frames are copied into a numpy view
    of it, a plain memcpy.
    """

    def __init__(self, width: int, height: int,
                 data: Optional['array.array[int]'] = None) -> None:
        self.width, self.height = width, height
        size = width * height * 3
        self.data = data if data is not None else array.array('B', bytes(size))
        if not isinstance(self.data, array.array) or self.data.typecode != 'B' \
                or len(self.data) != size:
            raise ValueError(f'need an array.array of {size} unsigned bytes')
        self._view = np.frombuffer(self.data, dtype=np.uint8).reshape(height, width, 3)

    def fill_from_rgba(self, rgba: np.ndarray) -> 'array.array[int]':
        rgba = np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.width, 4)
        self._view[...] = rgba[:, :, :3]
        return self.data


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
