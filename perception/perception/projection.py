"""From pixels to the belt: rays through the pinhole model, meeting a horizontal plane, and a
model-based correction for a cube's silhouette (its visible sides shift the blob's centroid
away from the top face's centre under perspective)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

import cv2
import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics K (3x3) and the optical frame's pose in the world (z forward, x right, y
    down): rotation ``rotation`` (columns: optical axes in world) and ``position``."""

    k: np.ndarray
    rotation: np.ndarray
    position: np.ndarray

    def ray(self, u: float, v: float) -> np.ndarray:
        """Unit direction (world) of the ray through pixel (u, v)."""
        d = np.linalg.solve(self.k, np.array([u, v, 1.0]))
        d = self.rotation @ d
        return np.asarray(d / np.linalg.norm(d))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (n x 2) of world points (n x 3) in front of the camera."""
        cam = (np.asarray(points, float) - self.position) @ self.rotation
        uvw = cam @ self.k.T
        return np.asarray(uvw[:, :2] / uvw[:, 2:3])


# The widest half field of view a pinhole camera_info may describe [degrees].
_HALF_FOV_LIMIT_DEG = 89.5
_WIDEST = math.tan(math.radians(_HALF_FOV_LIMIT_DEG))


def intrinsics_problem(width: int, height: int, k: ArrayLike) -> str:
    """Why a camera_info cannot be used ('' if it can): a size, and a pinhole K (row-major 3x3)
    that is finite, with positive focal lengths, the principal point inside the image,
    (0, 0, 1) as its last row and a field of view under 179 degrees."""
    values = np.asarray(k, float).ravel()
    if width <= 0 or height <= 0:
        return f'size {width}x{height}'
    if values.size != 9:
        return f'K has {values.size} values, not 9'
    if not np.all(np.isfinite(values)):
        return f'K is not finite: {values.tolist()}'
    fx, skew, cx, _, fy, cy = values[:6]
    if not (fx > 0.0 and fy > 0.0):
        return f'focal lengths fx {fx:g}, fy {fy:g} must be > 0'
    if not (0.0 < cx < width and 0.0 < cy < height):
        return f'principal point ({cx:g}, {cy:g}) outside the {width}x{height} image'
    if values[6:].tolist() != [0.0, 0.0, 1.0]:
        return f"K's last row is {values[6:].tolist()}, not [0, 0, 1]"
    # A focal length of 1e-300 pixels passed the checks above and made every ray sideways.
    if (max(cx, width - cx) / fx > _WIDEST or max(cy, height - cy) / fy > _WIDEST):
        return (f'focal lengths fx {fx:g}, fy {fy:g} give a {width}x{height} image a field of '
                f'view of {2 * _HALF_FOV_LIMIT_DEG:g} degrees or more')
    if abs(skew) > max(fx, fy):
        return f'skew {skew:g} exceeds the focal length'
    return ''


def pixel_to_plane(camera: CameraModel, u: float, v: float, plane_z: float) -> np.ndarray:
    """Where the ray through (u, v) meets the horizontal plane z = plane_z (world)."""
    d = camera.ray(u, v)
    if abs(d[2]) < 1e-9:
        raise ValueError('the ray is parallel to the plane')
    t = (plane_z - camera.position[2]) / d[2]
    if t <= 0.0:
        raise ValueError('the plane is behind the camera')
    return np.asarray(camera.position + t * d)


def cube_silhouette_centroid(camera: CameraModel, centre: ArrayLike, size: float,
                             yaw: float) -> np.ndarray:
    """Pixel centroid of the projected outline (convex hull) of an upright cube."""
    h = size / 2
    c, s = np.cos(yaw), np.sin(yaw)
    corners = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pixels = camera.project(corners @ rot.T + np.asarray(centre, float))
    hull = cv2.convexHull(pixels.astype(np.float32)).reshape(-1, 2).astype(float)
    x, y = hull[:, 0], hull[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = cross.sum() / 2
    return np.array([((x + x1) * cross).sum() / (6 * area), ((y + y1) * cross).sum() / (6 * area)])


def locate_cube(camera: CameraModel, u: float, v: float, support_z: float, size: float,
                yaw: float = 0.0, iterations: int = 4) -> Tuple[np.ndarray, float]:
    """Centre of an upright cube resting on the plane z = support_z whose silhouette centroid
    is at (u, v); returns (centre, residual in pixels). Starts from the ray meeting the cube's
    mid-height plane and corrects with the silhouette model (Newton steps on x, y)."""
    z = support_z + size / 2
    centre = pixel_to_plane(camera, u, v, z)
    target = np.array([u, v])
    for _ in range(iterations):
        predicted = cube_silhouette_centroid(camera, centre, size, yaw)
        error = target - predicted
        if np.linalg.norm(error) < 1e-4:
            break
        jac = np.empty((2, 2))
        for j in range(2):
            step = np.zeros(3)
            step[j] = 1e-4
            jac[:, j] = (cube_silhouette_centroid(camera, centre + step, size, yaw)
                         - predicted) / 1e-4
        centre[:2] += np.linalg.solve(jac, error)
    residual = float(np.linalg.norm(target - cube_silhouette_centroid(camera, centre, size,
                                                                        yaw)))
    return centre, residual
