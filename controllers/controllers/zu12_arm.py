"""The JAKA Zu 12's standard DH table (ROBOT_MODELS.md §4), base at the floor, tool at flange."""
from __future__ import annotations

import math

from controllers.dh_chain import STANDARD, DHChain, DHRow

# (d, a, alpha in degrees); all theta offsets are 0. The mirror-image table that circulates
# (d4 = +0.1315, alpha5 = +90) is a different robot.
_ROWS = ((0.14265, 0.0, 90.0), (0.0, 0.595, 0.0), (0.0, 0.5715, 0.0), (-0.1315, 0.0, 90.0),
         (0.115, 0.0, -90.0), (0.1035, 0.0, 0.0))
LIMITS_DEG = ((-360.0, 360.0), (-85.0, 265.0), (-175.0, 175.0), (-85.0, 265.0),
              (-360.0, 360.0), (-360.0, 360.0))
JOINT_SPEED_LIMITS_DEG_S = (120.0, 120.0, 120.0, 180.0, 180.0, 180.0)


def zu12_chain() -> DHChain:
    rows = tuple(DHRow(math.radians(alpha), a, d, 0.0, math.radians(lo), math.radians(hi))
                 for (d, a, alpha), (lo, hi) in zip(_ROWS, LIMITS_DEG))
    return DHChain(rows, STANDARD)
