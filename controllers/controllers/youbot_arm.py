"""The youBot arm's MDH table from the pipeline paper, read as docs/robot-models.md §3 explains."""
from __future__ import annotations

import math
from functools import lru_cache
from typing import List, Tuple

import numpy as np

from controllers.arrays import Vector
from controllers.dh_chain import MODIFIED, DHChain, DHRow

# The paper's Table 1 rows describe the arm only when row i is read as (a_i, alpha_i); in
# Craig's form (alpha_{i-1}, a_{i-1}, d_i) the table is:
CRAIG_ROWS_DEG_M = ((0.0, 0.0, 0.147), (90.0, 0.033, 0.0), (0.0, 0.155, 0.0),
                     (0.0, 0.135, 0.0), (-90.0, 0.0, 0.113))
# The paper's limits (degrees) are in the datasheet convention: zero at the "candle" pose.
DATASHEET_LIMITS_DEG = ((-169.0, 169.0), (-65.0, 90.0), (-151.0, 146.0), (-102.0, 102.0),
                        (-167.0, 167.0))
# theta = SIGN * phi + OFFSET maps datasheet angles phi to the table's theta.
THETA_SIGN = np.array([1.0, -1.0, -1.0, -1.0, 1.0])
THETA_OFFSET_RAD = np.radians([0.0, 90.0, 0.0, -90.0, 0.0])
# Velocity limit of every joint [rad/s].
JOINT_VELOCITY_LIMIT = math.pi / 2
# Acceleration and jerk limits: not in the datasheet. Assumed, and what the simulated joints
# follow without lagging [rad/s^2, rad/s^3].
JOINT_ACCELERATION_LIMIT = 6.0
JOINT_JERK_LIMIT = 60.0
# The robot description's joints use the datasheet angles (zero at the candle, positive as in
# the datasheet); its names, and where the table's frame 0 sits on base_link [m].
JOINT_NAMES = tuple(f'arm_joint_{i}' for i in range(1, 6))
ARM_BASE_IN_BASE_LINK_M = (0.167, 0.0, 0.014)
# Grasp point of the two-finger gripper on the approach axis, beyond the joint-5 flange [m]
# (0.2176 from joint 4, of which d5 = 0.113 is the flange).
GRIPPER_TCP_OFFSET_M = 0.2176 - 0.113


def theta_from_datasheet(phi: Vector) -> np.ndarray:
    """theta1 = phi1, theta2 = 90 deg - phi2, theta3 = -phi3, theta4 = -90 deg - phi4,
    theta5 = phi5 (radians)."""
    theta: np.ndarray = THETA_SIGN * np.asarray(phi, float) + THETA_OFFSET_RAD
    return theta


def datasheet_from_theta(theta: Vector) -> np.ndarray:
    phi: np.ndarray = (np.asarray(theta, float) - THETA_OFFSET_RAD) * THETA_SIGN
    return phi


def _theta_limits() -> List[Tuple[float, float]]:
    limits = []
    for i, (lo, hi) in enumerate(DATASHEET_LIMITS_DEG):
        a, b = sorted(float(THETA_SIGN[i] * math.radians(v) + THETA_OFFSET_RAD[i])
                      for v in (lo, hi))
        limits.append((a, b))
    return limits


@lru_cache(maxsize=None)
def youbot_arm_chain() -> DHChain:
    """The 5-joint arm in the table's theta, from the arm base frame to the joint-5 flange."""
    rows = tuple(DHRow(math.radians(alpha), a, d, 0.0, lo, hi) for (alpha, a, d), (lo, hi)
                 in zip(CRAIG_ROWS_DEG_M, _theta_limits()))
    return DHChain(rows, MODIFIED)
