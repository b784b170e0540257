"""Analytic inverse kinematics of the youBot's 5-joint arm (in the MDH table's theta).

Joint 1 turns the arm's plane; joints 2, 3, 4 are parallel and move the wrist in that plane;
joint 5 turns the gripper about the approach direction (the tool z axis). So the reachable
poses are a position plus an approach direction lying in the arm's plane, plus a rotation
about the approach: for those there are up to four closed-form solutions (the arm's plane
turned by pi, elbow up or down).
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence

import numpy as np

from controllers.dh_chain import DHChain, IKResult
from controllers.youbot_arm import youbot_arm_chain

_SHOULDER_R, _SHOULDER_Z = 0.033, 0.147     # joint 2's axis in the arm plane
_L2, _L3, _WRIST = 0.155, 0.135, 0.113       # links 2 and 3, joint 4 to the flange
PLANE_TOLERANCE = 1e-6                       # |approach . plane normal| accepted


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def solve_ik(target: np.ndarray, q_seed: Optional[Sequence[float]] = None,
             chain: Optional[DHChain] = None) -> IKResult:
    """Joint values (table theta) whose flange pose is ``target`` (4x4), nearest to the seed.
    In plain float arithmetic (numpy's per-call overhead was most of a solve)."""
    chain = chain or youbot_arm_chain()
    if chain.has_tool:
        raise ValueError('solve_ik solves for the flange: give it a chain without a tool')
    target = np.asarray(target, float)
    if target.shape != (4, 4) or not np.all(np.isfinite(target)):
        return IKResult(False, reason='target must be a finite 4x4 pose')
    seed = [0.0] * 5 if q_seed is None else [float(v) for v in q_seed]
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz), _ = target.tolist()
    ax, ay, az = r02, r12, r22                        # the approach (tool z)
    wx, wy, wz = px - _WRIST * ax, py - _WRIST * ay, pz - _WRIST * az
    radial = math.hypot(wx, wy)
    if radial > 1e-9:
        bases = [math.atan2(wy, wx)]
    else:  # wrist centre on joint 1's axis: the plane follows the approach, or the seed
        horizontal = math.hypot(ax, ay)
        bases = [math.atan2(ay, ax) if horizontal > 1e-9 else seed[0]]
    lower, upper = chain.limits
    lower, upper = lower.tolist(), upper.tolist()
    candidates, reasons = [], set()
    for base in bases:
        for theta1, sign in ((base, 1.0), (_wrap(base + math.pi), -1.0)):
            c1, s1 = math.cos(theta1), math.sin(theta1)
            if abs(-s1 * ax + c1 * ay) > PLANE_TOLERANCE:      # approach . the plane's normal
                reasons.add('approach direction not in the arm plane (a 5-joint arm cannot)')
                continue
            r = sign * radial - _SHOULDER_R
            z = wz - _SHOULDER_Z
            c3 = (r * r + z * z - _L2 * _L2 - _L3 * _L3) / (2 * _L2 * _L3)
            if c3 > 1 + 1e-12 or c3 < -1 - 1e-12:
                reasons.add('out of reach')
                continue
            c3 = max(-1.0, min(1.0, c3))
            psi = math.atan2(az, c1 * ax + s1 * ay)      # the approach in the plane
            for theta3 in {math.acos(c3), -math.acos(c3)}:
                theta2 = math.atan2(z, r) - math.atan2(_L3 * math.sin(theta3),
                                                       _L2 + _L3 * math.cos(theta3))
                theta4 = _wrap(psi - math.pi / 2 - theta2 - theta3)
                q = [theta1, _wrap(theta2), theta3, theta4, 0.0]
                # theta5: the remaining rotation about the approach, from the tool's x axis
                # with joint 5 at zero (n) to the target's (x): atan2((n x x) . a, n . x).
                pose = chain.fk_rows(q)
                n = (pose[0], pose[4], pose[8])
                cross_a = ((n[1] * r20 - n[2] * r10) * ax + (n[2] * r00 - n[0] * r20) * ay
                           + (n[0] * r10 - n[1] * r00) * az)
                q[4] = math.atan2(cross_a, n[0] * r00 + n[1] * r10 + n[2] * r20)
                candidates.append(_into_limits(q, lower, upper))
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
    valid = [np.array(q) for q in valid]
    best = np.array(best)
    if pos_err > 1e-6 or rot_err > 1e-6:
        return IKResult(False, best, 'no exact solution for this pose', pos_err, rot_err,
                        valid)
    return IKResult(True, best, '', pos_err, rot_err, valid)


def _into_limits(q: List[float], lower: List[float], upper: List[float]
                 ) -> Optional[List[float]]:
    """The same pose with each angle shifted by 2 pi into its limits, or None if impossible."""
    out = list(q)
    for i, value in enumerate(q):
        for shift in (0.0, 2 * math.pi, -2 * math.pi):
            if lower[i] - 1e-9 <= value + shift <= upper[i] + 1e-9:
                out[i] = min(max(value + shift, lower[i]), upper[i])
                break
        else:
            return None
    return out
