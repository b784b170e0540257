"""How well a base followed a constant body twist: the measures of the base fidelity tests and
benchmark (odometry against the commanded twist, and the drift across the commanded path)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

from controllers.diff_drive import Pose2D, wrap_angle


def integrate_twist(pose: Pose2D, vx: float, vy: float, wz: float, dt: float) -> Pose2D:
    """Exact pose after holding the body twist (vx, vy, wz) for dt from ``pose``."""
    if dt < 0.0:
        raise ValueError(f'dt must be >= 0, got {dt}')
    th0 = pose.yaw
    if abs(wz) < 1e-12:
        c, s = math.cos(th0), math.sin(th0)
        return Pose2D(pose.x + (vx * c - vy * s) * dt, pose.y + (vx * s + vy * c) * dt, th0)
    th1 = th0 + wz * dt
    ds, dc = math.sin(th1) - math.sin(th0), math.cos(th1) - math.cos(th0)
    return Pose2D(pose.x + (vx * ds + vy * dc) / wz, pose.y + (-vx * dc + vy * ds) / wz,
                  wrap_angle(th1))


@dataclass(frozen=True)
class TrackingErrors:
    """Relative errors of a motion against the ideal motion of its commanded twist."""

    path_length: float        # distance the commanded twist moves base_link [m]
    position_error: float     # |actual - ideal| / path length (or / wheel distance, if turning)
    cross_drift: float        # part of that error across the ideal displacement, same scale
    yaw_error: float          # |actual - ideal yaw| / |commanded turn| (0 if no turn)
    twist_error: float        # max over commanded components of |measured - cmd| / |cmd|


def tracking_errors(command: Tuple[float, float, float], duration: float, start: Pose2D,
                    end: Pose2D, measured_twist: Tuple[float, float, float],
                    turn_radius: float) -> TrackingErrors:
    """Compare a motion from ``start`` to ``end`` (odometry) with the commanded twist.

    ``turn_radius`` scales a pure rotation: its drift is relative to the distance the wheels
    travel (turn angle x turn_radius, with turn_radius = lx + ly for a Mecanum base).
    """
    vx, vy, wz = command
    ideal = integrate_twist(start, vx, vy, wz, duration)
    path = math.hypot(vx, vy) * duration
    scale = path if path > 1e-9 else abs(wz) * duration * turn_radius
    if scale <= 0.0:
        raise ValueError('a zero command has no tracking error')
    ex, ey = end.x - ideal.x, end.y - ideal.y
    dx, dy = ideal.x - start.x, ideal.y - start.y
    norm = math.hypot(dx, dy)
    if norm > 1e-9:
        cross = abs(ex * dy - ey * dx) / norm
    else:                       # turning in place: any translation is drift
        cross = math.hypot(end.x - start.x, end.y - start.y)
    turn = abs(wz) * duration
    yaw_error = abs(wrap_angle(end.yaw - ideal.yaw)) / turn if turn > 1e-9 else 0.0
    twist_error = max((abs(m - c) / abs(c) for m, c in zip(measured_twist, command)
                       if abs(c) > 1e-9), default=0.0)
    return TrackingErrors(path, math.hypot(ex, ey) / scale, cross / scale, yaw_error,
                          twist_error)
