"""Serial chains from Denavit-Hartenberg tables, in Craig's modified or the standard convention."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import List, Optional, Tuple

import numpy as np

from controllers.arrays import Vector

MODIFIED, STANDARD = 'modified', 'standard'


@dataclass
class IKResult:
    """An inverse-kinematics answer: joint values on success, else the reason."""

    success: bool
    q: Optional[np.ndarray] = None
    reason: str = ''
    position_error: float = math.inf
    rotation_error: float = math.inf
    candidates: List[np.ndarray] = field(default_factory=list)
    # The answer's flange pose (before the chain's tool) as fk_rows gives it, when the solver
    # computed it to check the answer: callers need not compute it again.
    flange_rows: Optional[Tuple[float, ...]] = None


@dataclass(frozen=True)
class DHRow:
    """One joint. Modified (Craig): alpha and a are alpha_{i-1}, a_{i-1} of the link before the
    joint. Standard: alpha and a of the link after it. Angles in radians, lengths in metres."""

    alpha: float
    a: float
    d: float
    theta_offset: float = 0.0
    lower: float = -math.pi
    upper: float = math.pi

    def __post_init__(self) -> None:
        values = (self.alpha, self.a, self.d, self.theta_offset, self.lower, self.upper)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'DH row values must be finite: {self}')
        if self.lower > self.upper:
            raise ValueError(f'lower limit {self.lower} above upper limit {self.upper}')


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, c, -s, 0.0], [0.0, s, c, 0.0],
                     [0.0, 0.0, 0.0, 1.0]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                     [0.0, 0.0, 0.0, 1.0]])


def _trans(x: float = 0.0, z: float = 0.0) -> np.ndarray:
    t = np.eye(4)
    t[0, 3], t[2, 3] = x, z
    return t


@dataclass(frozen=True)
class DHChain:
    """Revolute joints described by DH rows, with an optional fixed tool transform."""

    rows: Tuple[DHRow, ...]
    convention: str = MODIFIED
    tool: Tuple[Tuple[float, ...], ...] = tuple(map(tuple, np.eye(4)))

    def __post_init__(self) -> None:
        if self.convention not in (MODIFIED, STANDARD):
            raise ValueError(f'convention must be "{MODIFIED}" or "{STANDARD}"')
        if not self.rows:
            raise ValueError('a chain needs at least one row')

    @property
    def dof(self) -> int:
        return len(self.rows)

    @property
    def limits(self) -> Tuple[np.ndarray, np.ndarray]:
        return (np.array([r.lower for r in self.rows]), np.array([r.upper for r in self.rows]))

    @cached_property
    def limit_lists(self) -> Tuple[List[float], List[float]]:
        """The limits as lists of floats, for solvers in float arithmetic (do not modify)."""
        return [r.lower for r in self.rows], [r.upper for r in self.rows]

    def within_limits(self, q: Vector, tol: float = 1e-9) -> bool:
        lower, upper = self.limits
        q = np.asarray(q, float)
        return bool(np.all(q >= lower - tol) and np.all(q <= upper + tol))

    def joint_transform(self, i: int, q_i: float) -> np.ndarray:
        """Transform from frame i-1 to frame i at joint value q_i."""
        r = self.rows[i]
        theta = q_i + r.theta_offset
        transform: np.ndarray
        if self.convention == MODIFIED:
            transform = _rot_x(r.alpha) @ _trans(x=r.a) @ _rot_z(theta) @ _trans(z=r.d)
        else:
            transform = _rot_z(theta) @ _trans(z=r.d) @ _trans(x=r.a) @ _rot_x(r.alpha)
        return transform

    def frames(self, q: Vector) -> List[np.ndarray]:
        """Base-frame poses of frames 1..n (joint frames), then the tool frame."""
        q = self._check(q)
        t = np.eye(4)
        out = []
        for i, qi in enumerate(q):
            t = t @ self.joint_transform(i, qi)
            out.append(t)
        out.append(t @ np.asarray(self.tool))
        return out

    def fk(self, q: Vector) -> np.ndarray:
        """4x4 pose of the tool frame in the base frame. In plain float arithmetic (each joint's
        transform multiplied out by hand), about ten times faster than ``frames(q)[-1]``,
        which gives the same pose."""
        r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz = self.fk_rows(q)
        pose = np.array(((r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz),
                         (0.0, 0.0, 0.0, 1.0)))
        return pose if not self.has_tool else pose @ self._tool_matrix

    def fk_rows(self, q: Vector, origins: Optional[List[Tuple[float, float, float]]] = None
                ) -> Tuple[float, ...]:
        """The flange's pose (before the tool) as the 12 floats of its top three rows, row by
        row: for callers that do their own float arithmetic (the analytic IK). ``origins``, a
        list, receives the base-frame origin (x, y, z) of every joint frame 1..n."""
        values = self._values(q)
        # The rotation's columns (x0.., x1.., x2..) and the origin, right-multiplied joint by
        # joint: RotX and RotZ mix two columns, TransX and TransZ add a column to the origin.
        x0, y0, z0, x1, y1, z1, x2, y2, z2 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px = py = pz = 0.0
        modified = self.convention == MODIFIED
        for (ca, sa, a, d, offset, twisted), qi in zip(self._constants, values):
            ct, st = math.cos(qi + offset), math.sin(qi + offset)
            if modified:     # RotX(alpha) TransX(a) RotZ(theta) TransZ(d)
                if twisted:
                    x1, y1, z1, x2, y2, z2 = (ca * x1 + sa * x2, ca * y1 + sa * y2,
                                              ca * z1 + sa * z2, ca * x2 - sa * x1,
                                              ca * y2 - sa * y1, ca * z2 - sa * z1)
                if a:
                    px, py, pz = px + a * x0, py + a * y0, pz + a * z0
                x0, y0, z0, x1, y1, z1 = (ct * x0 + st * x1, ct * y0 + st * y1,
                                          ct * z0 + st * z1, ct * x1 - st * x0,
                                          ct * y1 - st * y0, ct * z1 - st * z0)
                if d:
                    px, py, pz = px + d * x2, py + d * y2, pz + d * z2
            else:            # RotZ(theta) TransZ(d) TransX(a) RotX(alpha)
                x0, y0, z0, x1, y1, z1 = (ct * x0 + st * x1, ct * y0 + st * y1,
                                          ct * z0 + st * z1, ct * x1 - st * x0,
                                          ct * y1 - st * y0, ct * z1 - st * z0)
                if d:
                    px, py, pz = px + d * x2, py + d * y2, pz + d * z2
                if a:
                    px, py, pz = px + a * x0, py + a * y0, pz + a * z0
                if twisted:
                    x1, y1, z1, x2, y2, z2 = (ca * x1 + sa * x2, ca * y1 + sa * y2,
                                              ca * z1 + sa * z2, ca * x2 - sa * x1,
                                              ca * y2 - sa * y1, ca * z2 - sa * z1)
            if origins is not None:
                origins.append((px, py, pz))
        return x0, x1, x2, px, y0, y1, y2, py, z0, z1, z2, pz

    @cached_property
    def _constants(self) -> Tuple[Tuple[float, float, float, float, float, bool], ...]:
        return tuple((math.cos(r.alpha), math.sin(r.alpha), r.a, r.d, r.theta_offset,
                      r.alpha != 0.0) for r in self.rows)

    @cached_property
    def _tool_matrix(self) -> np.ndarray:
        return np.asarray(self.tool, float)

    @cached_property
    def has_tool(self) -> bool:
        """A tool transform other than the identity follows the last joint."""
        return not np.array_equal(np.asarray(self.tool), np.eye(4))

    def _values(self, q: Vector) -> List[float]:
        """``q`` as floats, checked as ``_check`` does (without numpy's overhead)."""
        try:
            values = q.tolist() if isinstance(q, np.ndarray) and q.ndim == 1 else \
                [float(v) for v in q]
        except TypeError:
            raise ValueError(f'expected {self.dof} joint values, got {q!r}') from None
        if len(values) != self.dof or getattr(q, 'ndim', 1) != 1:
            raise ValueError(f'expected {self.dof} joint values, got shape '
                             f'{np.shape(q)}')
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'joint values must be finite, got {values}')
        return values

    def _check(self, q: Vector) -> np.ndarray:
        q = np.asarray(q, float)
        if q.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint values, got shape {q.shape}')
        if not np.all(np.isfinite(q)):
            raise ValueError(f'joint values must be finite, got {q.tolist()}')
        return q
