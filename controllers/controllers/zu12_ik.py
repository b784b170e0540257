"""Analytic inverse kinematics of the JAKA Zu 12 (standard DH, the UR-like geometry of
ROBOT_MODELS.md §4: joints 2, 3, 4 parallel, a shoulder offset d4, a spherical-free wrist).

With z1 = (sin q1, -cos q1, 0) the common direction of axes 2-4:
- the wrist point o5 = p - d6 z6 lies d4 along z1:  o5 . z1 = d4          -> q1 (two values)
- the flange lies d4 + d6 cos q5 along z1:           p . z1 = d4 + d6 c5 -> q5 (two values)
- z1 seen from the flange frame is (s5 c6, -s5 s6, c5)                    -> q6
- the planar 2-link arm (a2, a3) reaches frame 4's origin                 -> q3 (two), q2
- the sum q2 + q3 + q4 is the heading of x4 in frame 1                    -> q4
Up to eight solutions, each brought into the limits by turns of 2 pi (the Zu 12's joints 1, 5,
6 turn +-360 deg, so several representatives exist: the one nearest the seed is used), checked
by forward kinematics, and refined by damped least squares near singularities.
"""
from __future__ import annotations

import itertools
import math
from typing import List, Optional, Sequence

import numpy as np

from controllers.dh_chain import DHChain, IKResult
from controllers.zu12_arm import DH_ROWS, zu12_chain

_D1, _D4, _D5, _D6 = DH_ROWS[0][0], DH_ROWS[3][0], DH_ROWS[4][0], DH_ROWS[5][0]
_A2, _A3 = DH_ROWS[1][1], DH_ROWS[2][1]
TOLERANCE = 1e-9          # accepted position [m] and rotation [rad] residual


def solve_ik(target: np.ndarray, q_seed: Optional[Sequence[float]] = None,
             chain: Optional[DHChain] = None) -> IKResult:
    """Joint values whose flange pose is ``target`` (4x4 in the base frame), nearest the seed."""
    chain = chain or zu12_chain()
    target = np.asarray(target, float)
    if target.shape != (4, 4) or not np.all(np.isfinite(target)):
        return IKResult(False, reason='target must be a finite 4x4 pose')
    seed = np.zeros(6) if q_seed is None else np.asarray(q_seed, float)
    rot, p = target[:3, :3], target[:3, 3]
    x6, y6, z6 = rot[:, 0], rot[:, 1], rot[:, 2]
    o5 = p - _D6 * z6
    r = math.hypot(o5[0], o5[1])
    if r < abs(_D4) - 1e-12:
        return IKResult(False, reason='out of reach: the wrist is inside the shoulder offset '
                                      'cylinder')
    psi = math.atan2(o5[1], o5[0])
    offset = math.asin(max(-1.0, min(1.0, _D4 / r))) if r > 0.0 else 0.0
    reasons, raw = set(), []
    for q1 in (psi + offset, psi + math.pi - offset):
        z1 = np.array([math.sin(q1), -math.cos(q1), 0.0])
        c5 = (float(p @ z1) - _D4) / _D6
        if abs(c5) > 1.0 + 1e-9:
            reasons.add('out of reach: orientation incompatible with the wrist')
            continue
        c5 = max(-1.0, min(1.0, c5))
        for q5 in (math.acos(c5), -math.acos(c5)):
            s5 = math.sin(q5)
            if abs(s5) > 1e-9:
                q6 = math.atan2(-float(y6 @ z1) / s5, float(x6 @ z1) / s5)
            else:                      # wrist singular: q6 is free, keep the seed's
                q6 = seed[5]
            for sign in (1.0, -1.0):
                q = _arm(target, q1, q5, q6, sign, chain)
                if q is None:
                    reasons.add('out of reach')
                else:
                    raw.append(q)
    if not raw:
        return IKResult(False, reason=' and '.join(sorted(reasons)) or 'no solution')
    candidates = []
    for q in raw:
        q = _refine(chain, target, q)
        pos_err, rot_err = _errors(chain, q, target)
        if pos_err < TOLERANCE and rot_err < TOLERANCE:
            near = _nearest_in_limits(q, seed, chain)
            if near is not None:
                candidates.append(near)
    if not candidates:
        if any(_errors(chain, _refine(chain, target, q), target)[0] < TOLERANCE for q in raw):
            return IKResult(False, reason='every solution violates the joint limits')
        return IKResult(False, reason='out of reach')
    best = min(candidates, key=lambda q: float(np.abs(q - seed).sum()))
    pos_err, rot_err = _errors(chain, best, target)
    return IKResult(True, best, '', pos_err, rot_err, candidates)


def _arm(target: np.ndarray, q1: float, q5: float, q6: float, sign: float,
         chain: DHChain) -> Optional[np.ndarray]:
    """q2, q3, q4 for the given q1, q5, q6 and elbow sign, or None if out of reach: frame 4 in
    frame 1 is T01^-1 T T56^-1 T45^-1 (multiplied out in floats)."""
    t01 = chain.joint_transform(0, q1)
    t46 = chain.joint_transform(4, q5) @ chain.joint_transform(5, q6)
    # Inverses of rigid transforms: (R, p)^-1 = (R^T, -R^T p).
    r01, p01 = t01[:3, :3], t01[:3, 3]
    r46, p46 = t46[:3, :3], t46[:3, 3]
    r = r01.T @ target[:3, :3] @ r46.T
    p = r01.T @ (target[:3, 3] - p01) - r @ p46
    x, y = float(p[0]), float(p[1])
    c3 = (x * x + y * y - _A2 * _A2 - _A3 * _A3) / (2 * _A2 * _A3)
    if abs(c3) > 1.0 + 1e-9:
        return None
    q3 = sign * math.acos(max(-1.0, min(1.0, c3)))
    q2 = math.atan2(y, x) - math.atan2(_A3 * math.sin(q3), _A2 + _A3 * math.cos(q3))
    q4 = math.atan2(float(r[1, 0]), float(r[0, 0])) - q2 - q3
    return np.array([q1, q2, q3, q4, q5, q6])


def _errors(chain: DHChain, q: np.ndarray, target: np.ndarray):
    """Position error [m] and rotation angle [rad] of the flange at ``q`` from ``target``
    (float arithmetic on the FK's rows)."""
    r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz = chain.fk_rows(q)
    (t00, t01, t02, tx), (t10, t11, t12, ty), (t20, t21, t22, tz) = target[:3].tolist()
    pos = math.sqrt((px - tx) ** 2 + (py - ty) ** 2 + (pz - tz) ** 2)
    # rel = reached^T target: its trace and its skew part give the angle.
    m00 = r00 * t00 + r10 * t10 + r20 * t20
    m11 = r01 * t01 + r11 * t11 + r21 * t21
    m22 = r02 * t02 + r12 * t12 + r22 * t22
    m21 = r02 * t01 + r12 * t11 + r22 * t21
    m12 = r01 * t02 + r11 * t12 + r21 * t22
    m02 = r00 * t02 + r10 * t12 + r20 * t22
    m20 = r02 * t00 + r12 * t10 + r22 * t20
    m10 = r01 * t00 + r11 * t10 + r21 * t20
    m01 = r00 * t01 + r10 * t11 + r20 * t21
    s = math.sqrt((m21 - m12) ** 2 + (m02 - m20) ** 2 + (m10 - m01) ** 2)
    return pos, math.atan2(s / 2, (m00 + m11 + m22 - 1) / 2)


def _refine(chain: DHChain, target: np.ndarray, q: np.ndarray, iterations: int = 8
            ) -> np.ndarray:
    """A few damped Gauss-Newton steps on the pose error (only when not already exact)."""
    q = q.copy()
    for _ in range(iterations):
        pos_err, rot_err = _errors(chain, q, target)
        if pos_err < TOLERANCE * 0.1 and rot_err < TOLERANCE * 0.1:
            break
        error = _pose_error(chain.fk(q), target)
        # Minus the Jacobian of the error, by forward differences.
        jac = np.empty((6, 6))
        h = 1e-7
        for j in range(6):
            dq = q.copy()
            dq[j] += h
            jac[:, j] = (error - _pose_error(chain.fk(dq), target)) / h
        q = q + np.linalg.solve(jac.T @ jac + 1e-12 * np.eye(6), jac.T @ error)
    return q


def _pose_error(reached: np.ndarray, target: np.ndarray) -> np.ndarray:
    """6-vector (position, rotation vector) from ``reached`` to ``target``, base frame."""
    dp = target[:3, 3] - reached[:3, 3]
    rel = target[:3, :3] @ reached[:3, :3].T
    angle = math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1) / 2)))
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    if angle < 1e-12:
        return np.concatenate([dp, axis / 2])
    return np.concatenate([dp, axis * angle / (2 * math.sin(angle))])


def _nearest_in_limits(q: np.ndarray, seed: np.ndarray, chain: DHChain
                       ) -> Optional[np.ndarray]:
    """The representative (each joint shifted by whole turns) within the limits nearest the
    seed, or None."""
    lower, upper = chain.limits
    options: List[List[float]] = []
    for i in range(len(q)):
        base = (q[i] + math.pi) % (2 * math.pi) - math.pi
        values = [base + k * 2 * math.pi for k in range(-2, 3)
                  if lower[i] - 1e-9 <= base + k * 2 * math.pi <= upper[i] + 1e-9]
        if not values:
            return None
        options.append(sorted(values, key=lambda v: abs(v - seed[i]))[:1])
    return np.array([min(max(v, lo), hi) for v, lo, hi in
                     zip(next(itertools.product(*options)), lower, upper)])
