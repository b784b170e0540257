"""Planar paths through key poses: cubic Bezier curves between key points, traversed by arc length.

As CoppeliaSim's Path (the pipeline paper, its section 4.2): key points (x, y) joined by cubic
Bezier segments whose control points follow the Catmull-Rom tangents, so the curve passes
through every key point with a continuous tangent. Headings are given per key point and blend
smoothly along each segment. A profile moves a target ("dummy") along the path with bounded
speed and acceleration; the same profile shape times a heading change (``MotionProfile.lasting``
stretches one to a given duration).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Sequence, Tuple

import numpy as np

Pose2D = Tuple[float, float, float]          # x [m], y [m], yaw [rad]
SAMPLES_PER_SEGMENT = 64


class PathError(ValueError):
    pass


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class BezierPath:
    """A path through ``key_poses`` ((x, y, yaw) each, at least two, consecutive points apart)."""

    def __init__(self, key_poses: Sequence[Sequence[float]]) -> None:
        keys = np.asarray(key_poses, float)
        if keys.ndim != 2 or keys.shape[1] != 3 or len(keys) < 2:
            raise PathError('a path needs at least two key poses (x, y, yaw)')
        if not np.all(np.isfinite(keys)):
            raise PathError('key poses must be finite')
        points = keys[:, :2]
        if np.any(np.linalg.norm(np.diff(points, axis=0), axis=1) < 1e-6):
            raise PathError('consecutive key points must differ')
        self.key_poses = keys
        n = len(points)
        tangents = np.empty_like(points)
        tangents[0] = points[1] - points[0]
        tangents[-1] = points[-1] - points[-2]
        for i in range(1, n - 1):
            tangents[i] = (points[i + 1] - points[i - 1]) / 2.0
        # One cubic Bezier per segment: P0, P0 + T0/3, P1 - T1/3, P1.
        self.controls = np.array([[points[i], points[i] + tangents[i] / 3.0,
                                   points[i + 1] - tangents[i + 1] / 3.0, points[i + 1]]
                                  for i in range(n - 1)])
        # Arc-length table over a dense sampling of each segment.
        u = np.linspace(0.0, 1.0, SAMPLES_PER_SEGMENT + 1)
        pts = np.concatenate([_bezier(c, u[:-1] if i < n - 2 else u)
                              for i, c in enumerate(self.controls)])
        self._param = np.concatenate([i + u[:-1] if i < n - 2 else i + u
                                      for i in range(n - 1)])
        self._s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0),
                                                                  axis=1))])
        self.length = float(self._s[-1])
        # Key yaws unwrapped, so that a heading blends the short way round.
        yaws = keys[:, 2].copy()
        for i in range(1, n):
            yaws[i] = yaws[i - 1] + wrap_angle(yaws[i] - yaws[i - 1])
        self._yaws = yaws

    @property
    def heading_sweep(self) -> float:
        """How far the heading turns from the first key pose to the last, the way round the
        key poses go (signed, counter-clockwise positive) [rad]."""
        return float(self._yaws[-1] - self._yaws[0])

    def _parameter(self, s: float) -> float:
        s = min(max(s, 0.0), self.length)
        return float(np.interp(s, self._s, self._param))

    def pose(self, s: float) -> Pose2D:
        """The pose at arc length ``s`` (clamped to the path)."""
        param = self._parameter(s)
        i = min(int(param), len(self.controls) - 1)
        u = param - i
        x, y = _bezier(self.controls[i], np.array([u]))[0]
        blend = u * u * (3.0 - 2.0 * u)
        yaw = self._yaws[i] + blend * (self._yaws[i + 1] - self._yaws[i])
        return float(x), float(y), wrap_angle(float(yaw))

    def tangent(self, s: float) -> np.ndarray:
        """Unit direction of travel at arc length ``s``."""
        param = self._parameter(s)
        i = min(int(param), len(self.controls) - 1)
        d = _bezier_derivative(self.controls[i], param - i)
        return d / max(float(np.linalg.norm(d)), 1e-12)

    def sample(self, step: float = 0.02) -> np.ndarray:
        """Poses every ``step`` metres (for plots and checks)."""
        count = max(2, int(math.ceil(self.length / step)) + 1)
        return np.array([self.pose(s) for s in np.linspace(0.0, self.length, count)])


@dataclass(frozen=True)
class MotionProfile:
    """Where the dummy is along a path of ``length`` metres at time t after its start:
    trapezoidal (or triangular) speed with ``max_speed`` and ``max_accel``."""

    length: float
    max_speed: float
    max_accel: float

    def __post_init__(self) -> None:
        if not (self.max_speed > 0.0 and self.max_accel > 0.0 and self.length >= 0.0):
            raise PathError('a profile needs a length >= 0 and positive speed and acceleration')

    @classmethod
    def lasting(cls, length: float, duration: float, max_speed: float,
                max_accel: float) -> 'MotionProfile':
        """The profile over ``length`` at ``max_accel`` that takes ``duration``, its cruise speed
        lowered to stretch it (the fastest one if that takes longer than ``duration``)."""
        fastest = cls(length, max_speed, max_accel)
        if length <= 0.0 or duration <= fastest.duration:
            return fastest
        # A trapezoid at speed v lasts length / v + v / a: the lower root for the duration,
        # written as 2 a L / (a d + sqrt(...)), which keeps its digits for a tiny length (the
        # difference a d - sqrt(...) came to 0 for a turn of 1e-17 rad: no profile, and a
        # fleet's coordinator ended with a traceback).
        a = max_accel
        root = math.sqrt(max(0.0, (a * duration) ** 2 - 4.0 * a * length))
        speed = 2.0 * a * length / (a * duration + root)
        if not speed > 0.0:             # (a length of a few denormals: nothing to stretch)
            return fastest
        return cls(length, min(max_speed, speed), max_accel)

    @property
    def _ramp(self) -> Tuple[float, float]:
        """Time and distance of the acceleration ramp (reached speed)."""
        peak = min(self.max_speed, math.sqrt(self.length * self.max_accel))
        return peak / self.max_accel, peak

    @property
    def duration(self) -> float:
        t_ramp, peak = self._ramp
        if peak <= 0.0:
            return 0.0
        cruise = (self.length - peak * t_ramp) / peak
        return 2.0 * t_ramp + max(0.0, cruise)

    def at(self, t: float) -> Tuple[float, float]:
        """Arc length and speed at time ``t``."""
        t_ramp, peak = self._ramp
        total = self.duration
        if t <= 0.0 or total == 0.0:
            return 0.0, 0.0
        if t >= total:
            return self.length, 0.0
        a = self.max_accel
        if t < t_ramp:
            return 0.5 * a * t * t, a * t
        if t <= total - t_ramp:
            return 0.5 * peak * t_ramp + peak * (t - t_ramp), peak
        left = total - t
        return self.length - 0.5 * a * left * left, a * left


def _bezier(c: np.ndarray, u: np.ndarray) -> np.ndarray:
    u = u[:, None]
    v = 1.0 - u
    points: np.ndarray = (v ** 3 * c[0] + 3 * v * v * u * c[1] + 3 * v * u * u * c[2]
                          + u ** 3 * c[3])
    return points


def _bezier_derivative(c: np.ndarray, u: float) -> np.ndarray:
    v = 1.0 - u
    tangent: np.ndarray = (3 * v * v * (c[1] - c[0]) + 6 * v * u * (c[2] - c[1])
                           + 3 * u * u * (c[3] - c[2]))
    return tangent


def key_poses_between(start: Pose2D, goal: Pose2D, via: Sequence[Sequence[float]] = ()
                      ) -> List[Pose2D]:
    """Key poses from ``start`` through ``via`` points ((x, y) or (x, y, yaw)) to ``goal``; a
    via point without a heading takes the start's."""
    keys: List[Pose2D] = [(start[0], start[1], start[2])]
    for p in via:
        keys.append((p[0], p[1], p[2] if len(p) > 2 else start[2]))
    keys.append((goal[0], goal[1], goal[2]))
    return keys
