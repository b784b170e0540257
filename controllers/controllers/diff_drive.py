"""Differential-drive kinematics of the mini robot, as written in the mini-robot report."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Tuple

# The report's simulation parameters (docs/robot-models.md §1).
WHEEL_RADIUS_M = 0.03
WHEEL_SEPARATION_M = 0.113


@dataclass(frozen=True)
class DiffDriveGeometry:
    wheel_radius: float = WHEEL_RADIUS_M
    wheel_separation: float = WHEEL_SEPARATION_M

    def __post_init__(self) -> None:
        if not (self.wheel_radius > 0.0 and math.isfinite(self.wheel_radius)):
            raise ValueError(f'wheel_radius must be > 0, got {self.wheel_radius}')
        if not (self.wheel_separation > 0.0 and math.isfinite(self.wheel_separation)):
            raise ValueError(f'wheel_separation must be > 0, got {self.wheel_separation}')

    @property
    def half_track(self) -> float:
        """The report's b: distance of each wheel from the centre."""
        return 0.5 * self.wheel_separation


def wheel_speeds(v: float, w: float, geom: DiffDriveGeometry = DiffDriveGeometry()
                 ) -> Tuple[float, float]:
    """Return (left, right) wheel angular velocities [rad/s] for body twist (v [m/s], w [rad/s]).

    left = (v - b*w)/r, right = (v + b*w)/r, forward-positive for both wheels.
    """
    b, r = geom.half_track, geom.wheel_radius
    return (v - b * w) / r, (v + b * w) / r


def body_twist(w_left: float, w_right: float, geom: DiffDriveGeometry = DiffDriveGeometry()
               ) -> Tuple[float, float]:
    """Inverse of :func:`wheel_speeds`: v = r(wR + wL)/2, w = r(wR - wL)/(2b)."""
    r, b = geom.wheel_radius, geom.half_track
    return r * (w_right + w_left) / 2.0, r * (w_right - w_left) / (2.0 * b)


@dataclass(frozen=True)
class Pose2D:
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


def integrate_unicycle(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """Exact integration of a constant twist (v, w) held for dt (arc, or line when w = 0)."""
    if dt < 0.0:
        raise ValueError(f'dt must be >= 0, got {dt}')
    if abs(w) < 1e-12:
        return Pose2D(pose.x + v * dt * math.cos(pose.yaw),
                      pose.y + v * dt * math.sin(pose.yaw), pose.yaw)
    yaw1 = pose.yaw + w * dt
    radius = v / w
    return Pose2D(pose.x + radius * (math.sin(yaw1) - math.sin(pose.yaw)),
                  pose.y - radius * (math.cos(yaw1) - math.cos(pose.yaw)),
                  wrap_angle(yaw1))


def predict_pose(start: Pose2D, segments: Iterable[Tuple[float, float, float]]) -> Pose2D:
    """Pose after holding each (v, w, duration) segment in turn."""
    pose = start
    for v, w, duration in segments:
        pose = integrate_unicycle(pose, v, w, duration)
    return pose


def wrap_angle(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi

