"""Analytic inverse kinematics of the JAKA Zu 12 (standard DH, the UR-like geometry of
docs/robot-models.md §4: joints 2, 3, 4 parallel, a shoulder offset d4, a spherical-free wrist).

With z1 = (sin q1, -cos q1, 0) the common direction of axes 2-4:
- the wrist point o5 = p - d6 z6 lies d4 along z1:  o5 . z1 = d4          -> q1 (two values)
- the flange lies d4 + d6 cos q5 along z1:           p . z1 = d4 + d6 c5 -> q5 (two values)
- z1 seen from the flange frame is (s5 c6, -s5 s6, c5)                    -> q6
- the planar 2-link arm (a2, a3) reaches frame 4's origin                 -> q3 (two), q2
- the sum q2 + q3 + q4 is the heading of x4 in frame 1                    -> q4
Up to eight solutions, each brought into the limits by turns of 2 pi (the Zu 12's joints 1, 5,
6 turn +-360 deg, so several representatives exist: the one nearest the seed is used). The
answer is checked by forward kinematics, and refined by damped least squares when it is not
exact (near singularities, where the closed form clamps a cosine).

All in plain float arithmetic: numpy's per-call overhead was most of a solve (1.6 ms, now
tens of microseconds).
"""
from __future__ import annotations

import math
from typing import List, Optional, Set, Tuple

import numpy as np

from controllers.arrays import Vector
from controllers.dh_chain import DHChain, IKResult
from controllers.transforms import pose_distance
from controllers.zu12_arm import DH_ROWS, zu12_chain

_D1, _D4, _D5, _D6 = DH_ROWS[0][0], DH_ROWS[3][0], DH_ROWS[4][0], DH_ROWS[5][0]
_A2, _A3 = DH_ROWS[1][1], DH_ROWS[2][1]
TOLERANCE = 1e-9          # accepted position [m] and rotation [rad] residual
_TWO_PI = 2 * math.pi


def solve_ik(target: np.ndarray, q_seed: Optional[Vector] = None,
             chain: Optional[DHChain] = None) -> IKResult:
    """Joint values whose flange pose is ``target`` (4x4 in the base frame), nearest the seed.
    ``candidates``: the closed-form solutions within the limits, the answer first, then the
    others nearest the seed first. The answer is checked by forward kinematics; the others are
    exact unless the pose is singular (``pose_errors`` checks one)."""
    chain = chain or zu12_chain()
    target = np.asarray(target, float)
    rows = target.tolist() if target.shape == (4, 4) else None
    if rows is None or not all(math.isfinite(v) for row in rows for v in row):
        return IKResult(False, reason='target must be a finite 4x4 pose')
    seed = [0.0] * 6 if q_seed is None else [float(v) for v in q_seed]
    raw, reasons = _closed_form(rows, seed[5])
    if not raw:
        return IKResult(False, reason=' and '.join(sorted(reasons)) or 'no solution')
    lower, upper = chain.limit_lists
    candidates = [q for q in (_nearest_in_limits(q, seed, lower, upper) for q in raw)
                  if q is not None]
    candidates.sort(key=lambda q: _distance(q, seed))
    for i, candidate in enumerate(candidates):
        q, pos_err, rot_err, reached = _checked(chain, rows, target, candidate, seed, lower,
                                                upper)
        if q is not None:
            return IKResult(True, np.array(q), '', pos_err, rot_err,
                            [np.array(c) for c in [q] + candidates[i + 1:]], reached)
    free = [-math.inf] * 6, [math.inf] * 6
    if any(_checked(chain, rows, target, q, q, *free)[0] is not None for q in raw):
        return IKResult(False, reason='every solution violates the joint limits')
    return IKResult(False, reason='out of reach')


def pose_errors(chain: DHChain, q: Vector, target: np.ndarray) -> Tuple[float, float]:
    """Position error [m] and rotation angle [rad] of the flange at ``q`` from ``target``."""
    rows: List[List[float]] = np.asarray(target, float).tolist()
    return _errors(chain, q, rows)


def _closed_form(rows: List[List[float]], seed_q6: float
                 ) -> Tuple[List[List[float]], Set[str]]:
    """The (up to eight) closed-form solutions, not yet brought into the limits, and the
    reasons for the branches that have none."""
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz) = rows[:3]
    wx, wy = px - _D6 * r02, py - _D6 * r12                 # o5 = p - d6 z6
    radius = math.hypot(wx, wy)
    if radius < abs(_D4) - 1e-12:
        return [], {'out of reach: the wrist is inside the shoulder offset cylinder'}
    psi = math.atan2(wy, wx)
    offset = math.asin(max(-1.0, min(1.0, _D4 / radius))) if radius > 0.0 else 0.0
    raw: List[List[float]] = []
    reasons = set()
    for q1 in (psi + offset, psi + math.pi - offset):
        s1, c1 = math.sin(q1), math.cos(q1)
        c5 = (px * s1 - py * c1 - _D4) / _D6                 # z1 = (s1, -c1, 0)
        if abs(c5) > 1.0 + 1e-9:
            reasons.add('out of reach: orientation incompatible with the wrist')
            continue
        c5 = max(-1.0, min(1.0, c5))
        x6z1, y6z1 = r00 * s1 - r10 * c1, r01 * s1 - r11 * c1
        # Frame 4 in frame 1 is T01^-1 T T46^-1: with M = R01^T R (its rows m0, m1) and
        # u = R01^T (p - p01), R14 = M R46^T and p14 = u - R14 p46.
        m00, m01, m02 = c1 * r00 + s1 * r10, c1 * r01 + s1 * r11, c1 * r02 + s1 * r12
        u0, u1 = c1 * px + s1 * py, pz - _D1
        for q5 in (math.acos(c5), -math.acos(c5)):
            s5 = math.sin(q5)
            if abs(s5) > 1e-9:
                q6 = math.atan2(-y6z1 / s5, x6z1 / s5)
            else:                      # wrist singular: q6 is free, keep the seed's
                q6 = seed_q6
            s6, c6 = math.sin(q6), math.cos(q6)
            # Rows of R46 = R45 R56: g0, g1, g2; p46 = (-s5 d6, c5 d6, d5).
            g00, g01, g02 = c5 * c6, -c5 * s6, -s5
            g10, g11, g12 = s5 * c6, -s5 * s6, c5
            g20, g21 = -s6, -c6
            a00 = m00 * g00 + m01 * g01 + m02 * g02
            a01 = m00 * g10 + m01 * g11 + m02 * g12
            a02 = m00 * g20 + m01 * g21
            a10 = r20 * g00 + r21 * g01 + r22 * g02
            a11 = r20 * g10 + r21 * g11 + r22 * g12
            a12 = r20 * g20 + r21 * g21
            p0, p1, p2 = -s5 * _D6, c5 * _D6, _D5
            x = u0 - (a00 * p0 + a01 * p1 + a02 * p2)
            y = u1 - (a10 * p0 + a11 * p1 + a12 * p2)
            c3 = (x * x + y * y - _A2 * _A2 - _A3 * _A3) / (2 * _A2 * _A3)
            if abs(c3) > 1.0 + 1e-9:
                reasons.add('out of reach')
                continue
            elbow = math.acos(max(-1.0, min(1.0, c3)))
            heading = math.atan2(a10, a00)
            for q3 in (elbow, -elbow):
                q2 = math.atan2(y, x) - math.atan2(_A3 * math.sin(q3), _A2 + _A3 * math.cos(q3))
                raw.append([q1, q2, q3, heading - q2 - q3, q5, q6])
    return raw, reasons


def _checked(chain: DHChain, rows: List[List[float]], target: np.ndarray, q: List[float],
             seed: List[float], lower: List[float], upper: List[float]
             ) -> Tuple[Optional[List[float]], float, float, Optional[Tuple[float, ...]]]:
    """``q`` with its errors and its flange's rows if it reaches the target, refined (and
    brought back into the limits) when it is close but not exact; (None, inf, inf, None) if it
    does not reach it."""
    reached = chain.fk_rows(q)
    pos_err, rot_err = _distance_to(reached, rows)
    if pos_err < TOLERANCE and rot_err < TOLERANCE:
        return q, pos_err, rot_err, reached
    refined = _nearest_in_limits(_refine(chain, target, np.array(q)).tolist(), seed, lower,
                                 upper)
    if refined is not None:
        reached = chain.fk_rows(refined)
        pos_err, rot_err = _distance_to(reached, rows)
        if pos_err < TOLERANCE and rot_err < TOLERANCE:
            return refined, pos_err, rot_err, reached
    return None, math.inf, math.inf, None


def _distance(q: List[float], seed: List[float]) -> float:
    return sum(abs(a - b) for a, b in zip(q, seed))


def _errors(chain: DHChain, q: Vector, rows: List[List[float]]) -> Tuple[float, float]:
    """Position error [m] and rotation angle [rad] of the flange at ``q`` from the target's
    rows."""
    return _distance_to(chain.fk_rows(q), rows)


def _distance_to(reached: Tuple[float, ...], rows: List[List[float]]) -> Tuple[float, float]:
    return pose_distance((reached[0:4], reached[4:8], reached[8:12]), rows)


def _refine(chain: DHChain, target: np.ndarray, q: np.ndarray, iterations: int = 8
            ) -> np.ndarray:
    """A few damped Gauss-Newton steps on the pose error (only when not already exact)."""
    q = q.copy()
    rows = target.tolist()
    for _ in range(iterations):
        pos_err, rot_err = _errors(chain, q, rows)
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


def _nearest_in_limits(q: Vector, seed: Vector, lower: Vector,
                       upper: Vector) -> Optional[List[float]]:
    """The representative (each joint shifted by whole turns) within the limits nearest the
    seed, or None: the turn nearest the seed, else the next one towards the limits."""
    out = []
    for value, ref, lo, hi in zip(q, seed, lower, upper):
        v = value + _TWO_PI * round((ref - value) / _TWO_PI)
        if v < lo - 1e-9:
            v += _TWO_PI
        elif v > hi + 1e-9:
            v -= _TWO_PI
        if not lo - 1e-9 <= v <= hi + 1e-9:
            return None
        out.append(lo if v < lo else hi if v > hi else v)
    return out
