"""Homogeneous transforms and quaternions (x, y, z, w, as in geometry_msgs), in numpy."""
from __future__ import annotations

import math
from typing import Sequence, Tuple

import numpy as np

from controllers.arrays import Vector


def quaternion_to_matrix(q: Vector) -> np.ndarray:
    """3x3 rotation of a quaternion (x, y, z, w); it is normalised first."""
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not (n > 1e-12 and math.isfinite(n)):
        raise ValueError(f'quaternion {tuple(q)} has no direction')
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quaternion(r: np.ndarray) -> Tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) with w >= 0 of a 3x3 rotation (Shepperd's method)."""
    r = np.asarray(r, float)
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4)
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = (s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s)
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = ((r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = ((r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s)
    unit = np.array(q)
    unit /= np.linalg.norm(unit)
    if unit[3] < 0.0:
        unit = -unit
    x, y, z, w = (float(v) for v in unit)
    return (x, y, z, w)


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The rotation of roll, pitch and yaw about the fixed x, y and z axes (R = Rz Ry Rx, as
    URDF and tf2 take them)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def yaw_from_quaternion(q: Vector) -> float:
    """The yaw (about z) of a quaternion (x, y, z, w), as REP-103's roll-pitch-yaw has it."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def pose_matrix(position: Vector, quaternion: Vector) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = quaternion_to_matrix(quaternion)
    t[:3, 3] = [float(v) for v in position]
    return t


def translation(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def rotation_angle(r: np.ndarray) -> float:
    """Angle of a 3x3 rotation, accurate for small angles too."""
    r = np.asarray(r, float)
    s = np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2
    c = (np.trace(r) - 1.0) / 2
    return math.atan2(s, c)


def pose_distance(reached: Sequence[Vector], target: Sequence[Vector]
                  ) -> Tuple[float, float]:
    """Position distance [m] and rotation angle [rad] between two poses given as their top
    three rows (lists of floats, e.g. ``pose.tolist()``), in float arithmetic: a solver's
    check costs a few microseconds instead of numpy's tens."""
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz) = reached[:3]
    (t00, t01, t02, tx), (t10, t11, t12, ty), (t20, t21, t22, tz) = target[:3]
    pos = math.sqrt((px - tx) ** 2 + (py - ty) ** 2 + (pz - tz) ** 2)
    # rel = reached^T target: its trace and its skew part give the angle.
    m00 = r00 * t00 + r10 * t10 + r20 * t20
    m11 = r01 * t01 + r11 * t11 + r21 * t21
    m22 = r02 * t02 + r12 * t12 + r22 * t22
    m21 = r02 * t01 + r12 * t11 + r22 * t21
    m12 = r01 * t02 + r11 * t12 + r21 * t22
    m02 = r00 * t02 + r10 * t12 + r20 * t22
    m20 = r02 * t00 + r12 * t10 + r22 * t20
    m10 = r01 * t00 + r11 * t10 + r21 * t20
    m01 = r00 * t01 + r10 * t11 + r20 * t21
    s = math.sqrt((m21 - m12) ** 2 + (m02 - m20) ** 2 + (m10 - m01) ** 2)
    return pos, math.atan2(s / 2, (m00 + m11 + m22 - 1) / 2)
