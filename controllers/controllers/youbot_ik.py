"""Analytic inverse kinematics of the youBot's 5-joint arm (in the MDH table's theta).

Joint 1 turns the arm's plane; joints 2, 3, 4 are parallel and move the wrist in that plane;
joint 5 turns the gripper about the approach direction (the tool z axis). So the reachable
poses are a position plus an approach direction lying in the arm's plane, plus a rotation
about the approach: for those there are up to four closed-form solutions (the arm's plane
turned by pi, elbow up or down).
"""
from __future__ import annotations

import math
from typing import List, Optional, Set

import numpy as np

from controllers.arrays import Vector
from controllers.dh_chain import DHChain, IKResult
from controllers.youbot_arm import youbot_arm_chain

_SHOULDER_R, _SHOULDER_Z = 0.033, 0.147     # joint 2's axis in the arm plane
_L2, _L3, _WRIST = 0.155, 0.135, 0.113       # links 2 and 3, joint 4 to the flange
PLANE_TOLERANCE = 1e-6                       # |approach . plane normal| accepted
_TWO_PI = 2 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def solve_ik(target: np.ndarray, q_seed: Optional[Vector] = None,
             chain: Optional[DHChain] = None) -> IKResult:
    """Joint values (table theta) whose flange pose is ``target`` (4x4), nearest to the seed.
    In plain float arithmetic (numpy's per-call overhead was most of a solve)."""
    chain = chain or youbot_arm_chain()
    if chain.has_tool:
        raise ValueError('solve_ik solves for the flange: give it a chain without a tool')
    target = np.asarray(target, float)
    rows = target.tolist() if target.shape == (4, 4) else None
    if rows is None or not all(math.isfinite(v) for row in rows for v in row):
        return IKResult(False, reason='target must be a finite 4x4 pose')
    seed = [0.0] * 5 if q_seed is None else [float(v) for v in q_seed]
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz), _ = rows
    ax, ay, az = r02, r12, r22                        # the approach (tool z)
    wx, wy, wz = px - _WRIST * ax, py - _WRIST * ay, pz - _WRIST * az
    radial = math.hypot(wx, wy)
    if radial > 1e-9:
        bases = [math.atan2(wy, wx)]
    else:  # wrist centre on joint 1's axis: the plane follows the approach, or the seed
        horizontal = math.hypot(ax, ay)
        bases = [math.atan2(ay, ax) if horizontal > 1e-9 else seed[0]]
    lower, upper = chain.limit_lists
    candidates: List[Optional[List[float]]] = []
    reasons: Set[str] = set()
    for base in bases:
        for theta1, sign in ((base, 1.0), (_wrap(base + math.pi), -1.0)):
            candidates += _in_plane(theta1, sign * radial, wz, rows, lower, upper, reasons)
    if not candidates:
        return IKResult(False, reason=' and '.join(sorted(reasons)) or 'no solution')
    valid = [q for q in candidates if q is not None]
    if not valid:
        return IKResult(False, reason='every solution violates the joint limits',
                        candidates=[np.array(c) for c in candidates if c is not None])
    best = min(valid, key=lambda q: sum(abs(a - b) for a, b in zip(q, seed)))
    reached = chain.fk_rows(best)
    wanted = (r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz)
    pos_err = math.sqrt(sum((reached[k] - wanted[k]) ** 2 for k in (3, 7, 11)))
    rot_err = math.sqrt(sum((reached[k] - wanted[k]) ** 2 for k in (0, 1, 2, 4, 5, 6, 8, 9, 10)))
    solutions = [np.array(q) for q in valid]
    answer = np.array(best)
    if pos_err > 1e-6 or rot_err > 1e-6:
        return IKResult(False, answer, 'no exact solution for this pose', pos_err, rot_err,
                        solutions)
    return IKResult(True, answer, '', pos_err, rot_err, solutions, reached)


def _in_plane(theta1: float, r_wrist: float, z_wrist: float, rows: List[List[float]],
              lower: List[float], upper: List[float],
              reasons: Set[str]) -> List[Optional[List[float]]]:
    """The solutions with joint 1 at ``theta1`` (the wrist centre ``r_wrist`` out along the
    arm's plane, ``z_wrist`` high), each within the joint limits or None; why there are none,
    in ``reasons``."""
    (r00, _, ax, _), (r10, _, ay, _), (r20, _, az, _), _ = rows
    c1, s1 = math.cos(theta1), math.sin(theta1)
    if abs(-s1 * ax + c1 * ay) > PLANE_TOLERANCE:      # approach . the plane's normal
        reasons.add('approach direction not in the arm plane (a 5-joint arm cannot)')
        return []
    r = r_wrist - _SHOULDER_R
    z = z_wrist - _SHOULDER_Z
    c3 = (r * r + z * z - _L2 * _L2 - _L3 * _L3) / (2 * _L2 * _L3)
    if c3 > 1 + 1e-12 or c3 < -1 - 1e-12:
        reasons.add('out of reach')
        return []
    c3 = max(-1.0, min(1.0, c3))
    along = c1 * ax + s1 * ay                     # the approach in the plane
    psi = math.atan2(az, along)
    # theta5: the remaining rotation about the approach, from the tool's x axis with joint 5 at
    # zero (n) to the target's (x): atan2((n x x) . a, n . x). With
    # phi = theta2 + theta3 + theta4 = psi - pi/2, n = x4 = (c1 cos phi, s1 cos phi, sin phi)
    # and (cos phi, sin phi) = (az, -along) for a unit approach in the plane.
    n0, n1, n2 = c1 * az, s1 * az, -along
    cross_a = ((n1 * r20 - n2 * r10) * ax + (n2 * r00 - n0 * r20) * ay
               + (n0 * r10 - n1 * r00) * az)
    theta5 = math.atan2(cross_a, n0 * r00 + n1 * r10 + n2 * r20)
    elbow = math.acos(c3)
    out = []
    for theta3 in ((elbow, -elbow) if elbow else (elbow,)):
        theta2 = math.atan2(z, r) - math.atan2(_L3 * math.sin(theta3),
                                               _L2 + _L3 * math.cos(theta3))
        theta4 = _wrap(psi - math.pi / 2 - theta2 - theta3)
        out.append(_into_limits([theta1, _wrap(theta2), theta3, theta4, theta5], lower, upper))
    return out


def _into_limits(q: List[float], lower: List[float], upper: List[float]
                 ) -> Optional[List[float]]:
    """The same pose with each angle shifted by 2 pi into its limits, or None if impossible."""
    out = []
    for value, lo, hi in zip(q, lower, upper):
        lo_tol, hi_tol = lo - 1e-9, hi + 1e-9
        if not lo_tol <= value <= hi_tol:
            if lo_tol <= value + _TWO_PI <= hi_tol:
                value += _TWO_PI
            elif lo_tol <= value - _TWO_PI <= hi_tol:
                value -= _TWO_PI
            else:
                return None
        out.append(lo if value < lo else hi if value > hi else value)
    return out
