"""The JAKA Zu 12's standard DH table (docs/robot-models.md §4), base at the floor, tool at
the flange."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from controllers.dh_chain import STANDARD, DHChain, DHRow

# (d, a, alpha in degrees); all theta offsets are 0. The mirror-image table that circulates
# (d4 = +0.1315, alpha5 = +90) is a different robot.
DH_ROWS = ((0.14265, 0.0, 90.0), (0.0, 0.595, 0.0), (0.0, 0.5715, 0.0), (-0.1315, 0.0, 90.0),
           (0.115, 0.0, -90.0), (0.1035, 0.0, 0.0))
LIMITS_DEG = ((-360.0, 360.0), (-85.0, 265.0), (-175.0, 175.0), (-85.0, 265.0),
              (-360.0, 360.0), (-360.0, 360.0))
JOINT_SPEED_LIMITS_DEG_S = (120.0, 120.0, 120.0, 180.0, 180.0, 180.0)
JOINT_NAMES = tuple(f'joint_{i}' for i in range(1, 7))
# The description's joint positions are the table's theta (no offsets, same signs).
JOINT_VELOCITY_LIMITS = tuple(math.radians(v) for v in JOINT_SPEED_LIMITS_DEG_S)
# Acceleration and jerk limits: not published by JAKA. Assumed, of the order of other 10-12 kg
# cobots' (about 4x the speed limit per second; jerk 10x that), and what the simulated joints
# follow without lagging [rad/s^2, rad/s^3].
JOINT_ACCELERATION_LIMITS = (8.0, 8.0, 8.0, 12.0, 12.0, 12.0)
JOINT_JERK_LIMITS = (80.0, 80.0, 80.0, 120.0, 120.0, 120.0)
# The suction tool's contact point on the flange's z axis [m].
SUCTION_TCP_OFFSET_M = 0.1


@lru_cache(maxsize=None)
def zu12_chain() -> DHChain:
    rows = tuple(DHRow(math.radians(alpha), a, d, 0.0, math.radians(lo), math.radians(hi))
                 for (d, a, alpha), (lo, hi) in zip(DH_ROWS, LIMITS_DEG))
    return DHChain(rows, STANDARD)


def flange_offset(i: int) -> np.ndarray:
    """The fixed part of standard-DH row i: TransZ(d) TransX(a) RotX(alpha)."""
    d, a, alpha = DH_ROWS[i]
    c, s = math.cos(math.radians(alpha)), math.sin(math.radians(alpha))
    return np.array([[1.0, 0.0, 0.0, a], [0.0, c, -s, 0.0], [0.0, s, c, d],
                     [0.0, 0.0, 0.0, 1.0]])
