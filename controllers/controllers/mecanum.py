"""Mecanum-base kinematics of the KUKA youBot (the pipeline paper's eq. 9; docs/robot-models.md
§2)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

# The published description's wheel geometry: radius, and k = lx + ly (0.228 + 0.158).
WHEEL_RADIUS_M = 0.0475
LX_PLUS_LY_M = 0.386
# The youBot's base_link above the floor when it stands on its wheels (their axles 0.034 m
# below it).
BASE_LINK_HEIGHT_M = 0.0815

Wheels = Tuple[float, float, float, float]


@dataclass(frozen=True)
class MecanumGeometry:
    wheel_radius: float = WHEEL_RADIUS_M
    k: float = LX_PLUS_LY_M   # half wheelbase + half track

    def __post_init__(self) -> None:
        for name in ('wheel_radius', 'k'):
            value = getattr(self, name)
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f'{name} must be finite and > 0, got {value}')


def paper_wheel_speeds(vx: float, vy: float, wz: float,
                       geom: MecanumGeometry = MecanumGeometry()) -> Wheels:
    """The paper's eq. 9 as printed: w1..w4, each "seen from outside the wheel".

    w1 = (Vx - Vy - wz(a+b))/R, w2 = (-Vx - Vy - wz(a+b))/R,
    w3 = (-Vx + Vy - wz(a+b))/R, w4 = (Vx + Vy - wz(a+b))/R,
    with w1 front-left, w2 front-right, w3 rear-right, w4 rear-left.
    """
    r, k = geom.wheel_radius, geom.k
    return ((vx - vy - k * wz) / r, (-vx - vy - k * wz) / r,
            (-vx + vy - k * wz) / r, (vx + vy - k * wz) / r)


def paper_to_forward_positive(w: Wheels) -> Wheels:
    """Seen-from-outside speeds to forward-positive (FL, FR, RR, RL): the right-side wheels are
    seen from the other side, so their sign flips."""
    w1, w2, w3, w4 = w
    return (w1, -w2, -w3, w4)


def wheel_speeds(vx: float, vy: float, wz: float,
                 geom: MecanumGeometry = MecanumGeometry()) -> Wheels:
    """Forward-positive wheel speeds (FL, FR, RR, RL) [rad/s] for a body twist.

    The inverse kinematics of ros2_controllers' mecanum_drive_controller and of Modern Robotics
    eq. 13.10; equal to :func:`paper_to_forward_positive` of the paper's eq. 9.
    """
    r, k = geom.wheel_radius, geom.k
    return ((vx - vy - k * wz) / r, (vx + vy + k * wz) / r,
            (vx - vy + k * wz) / r, (vx + vy - k * wz) / r)


def body_twist(u: Wheels, geom: MecanumGeometry = MecanumGeometry()) -> Tuple[float, float,
                                                                              float]:
    """Forward kinematics (odometry): (vx, vy, wz) from forward-positive (FL, FR, RR, RL)."""
    fl, fr, rr, rl = u
    r, k = geom.wheel_radius, geom.k
    return (r / 4 * (fl + fr + rr + rl), r / 4 * (-fl + fr - rr + rl),
            r / (4 * k) * (-fl + fr + rr - rl))
