"""The youBot arm's MDH table from the pipeline paper, read as ROBOT_MODELS.md §3 explains."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from controllers.dh_chain import MODIFIED, DHChain, DHRow

# The paper's Table 1 rows describe the arm only when row i is read as (a_i, alpha_i); in
# Craig's form (alpha_{i-1}, a_{i-1}, d_i) the table is:
_CRAIG_ROWS_DEG_M = ((0.0, 0.0, 0.147), (90.0, 0.033, 0.0), (0.0, 0.155, 0.0),
                     (0.0, 0.135, 0.0), (-90.0, 0.0, 0.113))
# The paper's limits (degrees) are in the datasheet convention: zero at the "candle" pose.
DATASHEET_LIMITS_DEG = ((-169.0, 169.0), (-65.0, 90.0), (-151.0, 146.0), (-102.0, 102.0),
                        (-167.0, 167.0))
# theta = SIGN * phi + OFFSET maps datasheet angles phi to the table's theta.
_SIGN = np.array([1.0, -1.0, -1.0, -1.0, 1.0])
_OFFSET = np.radians([0.0, 90.0, 0.0, -90.0, 0.0])
# Velocity limit of every joint [rad/s].
JOINT_VELOCITY_LIMIT = math.pi / 2


def theta_from_datasheet(phi: Sequence[float]) -> np.ndarray:
    """theta1 = phi1, theta2 = 90 deg - phi2, theta3 = -phi3, theta4 = -90 deg - phi4,
    theta5 = phi5 (radians)."""
    return _SIGN * np.asarray(phi, float) + _OFFSET


def datasheet_from_theta(theta: Sequence[float]) -> np.ndarray:
    return (np.asarray(theta, float) - _OFFSET) * _SIGN


def _theta_limits() -> list:
    limits = []
    for i, (lo, hi) in enumerate(DATASHEET_LIMITS_DEG):
        ends = sorted(float(_SIGN[i] * math.radians(v) + _OFFSET[i]) for v in (lo, hi))
        limits.append(tuple(ends))
    return limits


def youbot_arm_chain() -> DHChain:
    """The 5-joint arm in the table's theta, from the arm base frame to the joint-5 flange."""
    rows = tuple(DHRow(math.radians(alpha), a, d, 0.0, lo, hi) for (alpha, a, d), (lo, hi)
                 in zip(_CRAIG_ROWS_DEG_M, _theta_limits()))
    return DHChain(rows, MODIFIED)
