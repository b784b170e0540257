"""Analytic inverse kinematics of the youBot's 5-joint arm (in the MDH table's theta).

Joint 1 turns the arm's plane; joints 2, 3, 4 are parallel and move the wrist in that plane;
joint 5 turns the gripper about the approach direction (the tool z axis). So the reachable
poses are a position plus an approach direction lying in the arm's plane, plus a rotation
about the approach: for those there are up to four closed-form solutions (the arm's plane
turned by pi, elbow up or down).
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

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
    """Joint values (table theta) whose flange pose is ``target`` (4x4), nearest to the seed."""
    chain = chain or youbot_arm_chain()
    target = np.asarray(target, float)
    if target.shape != (4, 4) or not np.all(np.isfinite(target)):
        return IKResult(False, reason='target must be a finite 4x4 pose')
    seed = np.zeros(5) if q_seed is None else np.asarray(q_seed, float)
    p, rot = target[:3, 3], target[:3, :3]
    approach = rot[:, 2]
    wrist = p - _WRIST * approach
    radial = math.hypot(wrist[0], wrist[1])
    if radial > 1e-9:
        bases = [math.atan2(wrist[1], wrist[0])]
    else:  # wrist centre on joint 1's axis: the plane follows the approach, or the seed
        horizontal = math.hypot(approach[0], approach[1])
        bases = [math.atan2(approach[1], approach[0]) if horizontal > 1e-9 else seed[0]]
    candidates, reasons = [], set()
    for base in bases:
        for theta1, sign in ((base, 1.0), (_wrap(base + math.pi), -1.0)):
            normal = np.array([-math.sin(theta1), math.cos(theta1), 0.0])
            if abs(float(approach @ normal)) > PLANE_TOLERANCE:
                reasons.add('approach direction not in the arm plane (a 5-joint arm cannot)')
                continue
            r = sign * radial - _SHOULDER_R
            z = wrist[2] - _SHOULDER_Z
            c3 = (r * r + z * z - _L2 * _L2 - _L3 * _L3) / (2 * _L2 * _L3)
            if c3 > 1 + 1e-12 or c3 < -1 - 1e-12:
                reasons.add('out of reach')
                continue
            c3 = max(-1.0, min(1.0, c3))
            forward = np.array([math.cos(theta1), math.sin(theta1), 0.0])
            psi = math.atan2(approach[2], float(approach @ forward))   # approach in the plane
            for theta3 in {math.acos(c3), -math.acos(c3)}:
                theta2 = math.atan2(z, r) - math.atan2(_L3 * math.sin(theta3),
                                                       _L2 + _L3 * math.cos(theta3))
                theta4 = _wrap(psi - math.pi / 2 - theta2 - theta3)
                q = np.array([theta1, _wrap(theta2), theta3, theta4, 0.0])
                # theta5: the remaining rotation about the approach.
                r04 = chain.fk(q)[:3, :3]
                x_now, x_want = r04[:, 0], rot[:, 0]
                q[4] = math.atan2(float(np.cross(x_now, x_want) @ approach),
                                  float(x_now @ x_want))
                candidates.append(_into_limits(q, chain))
    if not candidates:
        return IKResult(False, reason=' and '.join(sorted(reasons)) or 'no solution')
    valid = [q for q in candidates if q is not None]
    if not valid:
        return IKResult(False, reason='every solution violates the joint limits',
                        candidates=[c for c in candidates if c is not None])
    best = min(valid, key=lambda q: float(np.abs(q - seed).sum()))
    reached = chain.fk(best)
    pos_err = float(np.linalg.norm(reached[:3, 3] - p))
    rot_err = float(np.linalg.norm(reached[:3, :3] - rot))
    if pos_err > 1e-6 or rot_err > 1e-6:
        return IKResult(False, best, 'no exact solution for this pose', pos_err, rot_err,
                        valid)
    return IKResult(True, best, '', pos_err, rot_err, valid)


def _into_limits(q: np.ndarray, chain: DHChain) -> Optional[np.ndarray]:
    """The same pose with each angle shifted by 2 pi into its limits, or None if impossible."""
    lower, upper = chain.limits
    out = q.copy()
    for i in range(len(q)):
        for shift in (0.0, 2 * math.pi, -2 * math.pi):
            if lower[i] - 1e-9 <= q[i] + shift <= upper[i] + 1e-9:
                out[i] = min(max(q[i] + shift, lower[i]), upper[i])
                break
        else:
            return None
    return out
