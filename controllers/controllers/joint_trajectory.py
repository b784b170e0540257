"""Joint-trajectory following for a position-controlled joint group, without ROS.

Validation follows ros2_controllers' joint_trajectory_controller (unknown or duplicate joints,
empty trajectories, size mismatches, time_from_start order, non-finite values, position limits,
a start stamp so old that the whole trajectory lies in the past) and adds what it lets through:
a first point at time 0 away from the current position, segments faster than the joints'
velocity limits, given accelerations above the joints' acceleration limits, and an
interpolation that leaves the position limits or cannot be computed in floating point (a
first point's acceleration of 1e308 overflowed it into NaN, which reached the physics).
Interpolation, per segment:
- positions, velocities and accelerations given: quintic;
- positions (and optionally velocities): cubic Hermite. Missing velocities are chosen by
  monotone (Fritsch-Carlson) slopes, so an interpolated joint never overshoots its waypoints
  (and so never a limit that the waypoints respect); the last point ends at rest.
The trajectory starts from the controller's desired state when it is accepted, so a new
trajectory replaces the active one without a jump; joints left out hold where they are.
All times are seconds of the caller's (simulated) clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import numpy as np

from controllers.arrays import Vector

# A position "equals" the current one within this [rad or m] (first point at time 0).
START_TOLERANCE = 1e-3
LIMIT_TOLERANCE = 1e-9


# The interpolated reference may pass a position limit by this share of the joint's range
# (a cubic from a moving state may round a waypoint at the limit); beyond it, it is refused.
INTERPOLATION_MARGIN = 0.02
# Samples per segment at which the interpolation is checked against the position limits.
CHECK_SAMPLES = 9


@dataclass(frozen=True)
class JointLimits:
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    acceleration: Optional[np.ndarray] = None      # None: no limits (inf)

    def __post_init__(self) -> None:
        n = len(self.lower)
        if self.acceleration is None:
            object.__setattr__(self, 'acceleration', np.full(n, np.inf))
        if np.any(~(np.asarray(self.acceleration, float) > 0.0)):
            raise ValueError('limits: acceleration limits must be > 0')
        for name in ('upper', 'velocity', 'effort', 'acceleration'):
            if len(getattr(self, name)) != n:
                raise ValueError(f'limits: {name} has {len(getattr(self, name))} values, '
                                 f'lower has {n}')
        if np.any(np.asarray(self.lower) > np.asarray(self.upper)):
            raise ValueError('limits: a lower limit is above its upper limit')
        if np.any(np.asarray(self.velocity) <= 0.0):
            raise ValueError('limits: velocity limits must be > 0')


@dataclass(frozen=True)
class TrajectoryPoint:
    time_from_start: float
    positions: Tuple[float, ...]
    velocities: Tuple[float, ...] = ()
    accelerations: Tuple[float, ...] = ()
    effort: Tuple[float, ...] = ()


@dataclass(frozen=True)
class TrajectoryRequest:
    """A trajectory as received: ``start_time`` None (a zero stamp) means "start now"."""

    joint_names: Tuple[str, ...]
    points: Tuple[TrajectoryPoint, ...]
    start_time: Optional[float] = None


@dataclass
class TrajectoryResult:
    accepted: bool
    reason: str = ''


@dataclass
class _Segment:
    t0: float
    t1: float
    coeffs: np.ndarray          # (6, n): position polynomial in (t - t0), lowest order first


@dataclass
class DesiredState:
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


@dataclass
class _Active:
    segments: List[_Segment] = field(default_factory=list)
    end_time: float = -math.inf


class TrajectoryFollower:
    """Holds the desired state of one joint group and the trajectory it follows."""

    def __init__(self, joint_names: Sequence[str], limits: JointLimits,
                 positions: Vector) -> None:
        self.joint_names = tuple(joint_names)
        if len(set(self.joint_names)) != len(self.joint_names):
            raise ValueError(f'duplicate joint names {self.joint_names}')
        if len(limits.lower) != len(self.joint_names):
            raise ValueError('limits do not match the joints')
        self.limits = limits
        self._index = {name: i for i, name in enumerate(self.joint_names)}
        self.hold(positions)

    @property
    def active(self) -> bool:
        return bool(self._active.segments)

    def hold(self, positions: Vector) -> None:
        """Stop following and hold these positions."""
        n = len(self.joint_names)
        self._hold = np.array(positions, float).reshape(n)
        self._active = _Active()

    def validate(self, request: TrajectoryRequest, now: float,
                 current: Optional[Vector] = None) -> TrajectoryResult:
        """Check a trajectory; ``current`` is where the joints are (default: desired)."""
        names = request.joint_names
        if not names:
            return TrajectoryResult(False, 'no joint names')
        unknown = [n for n in names if n not in self._index]
        if unknown:
            return TrajectoryResult(False, f'unknown joints {unknown}; this controller has '
                                           f'{list(self.joint_names)}')
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            return TrajectoryResult(False, f'duplicate joint names {dup}')
        if not request.points:
            return TrajectoryResult(False, 'empty trajectory: no points')
        for name in ('velocities', 'accelerations'):
            given = [bool(getattr(p, name)) for p in request.points]
            if any(given) and not all(given):
                return TrajectoryResult(False, f'{name} given for some points but not all')
        idx = [self._index[n] for n in names]
        lower, upper = self.limits.lower[idx], self.limits.upper[idx]
        vmax = self.limits.velocity[idx]
        amax = np.asarray(self.limits.acceleration, float)[idx]
        if current is None:
            current = self.sample(now).positions
        start = now if request.start_time is None else request.start_time
        t_start = max(now, start)
        previous_t, previous_abs = -math.inf, t_start
        previous_q = np.asarray(current, float)[idx]
        for k, point in enumerate(request.points):
            reason = _check_point(point, k, len(names))
            if reason:
                return TrajectoryResult(False, reason)
            t = point.time_from_start
            if t < 0.0:
                return TrajectoryResult(False, f'point {k}: time_from_start {t:g} s is negative')
            if t <= previous_t:
                return TrajectoryResult(False, f'point {k}: time_from_start {t:g} s is not '
                                               f'after point {k - 1}\'s {previous_t:g} s')
            previous_t = t
            q = np.asarray(point.positions, float)
            out = (q < lower - LIMIT_TOLERANCE) | (q > upper + LIMIT_TOLERANCE)
            if np.any(out):
                j = int(np.argmax(out))
                return TrajectoryResult(False, f'point {k}: {names[j]} target {q[j]:.4f} is '
                                               f'outside its limits [{lower[j]:.4f}, '
                                               f'{upper[j]:.4f}]')
            if point.velocities:
                v = np.abs(np.asarray(point.velocities, float))
                if np.any(v > vmax + LIMIT_TOLERANCE):
                    j = int(np.argmax(v - vmax))
                    return TrajectoryResult(False, f'point {k}: {names[j]} velocity {v[j]:.4f} '
                                                   f'exceeds its limit {vmax[j]:.4f}')
            if point.accelerations:
                a = np.abs(np.asarray(point.accelerations, float))
                if np.any(a > amax * (1.0 + 1e-9)):
                    j = int(np.argmax(a - amax))
                    return TrajectoryResult(False, f'point {k}: {names[j]} acceleration '
                                                   f'{a[j]:.4g} exceeds its limit {amax[j]:.4g}')
            when = start + t
            if when < now:
                continue            # already past (an old stamp): skipped when following
            step = np.abs(q - previous_q)
            if when <= t_start:
                if np.any(step > START_TOLERANCE):
                    j = int(np.argmax(step))
                    return TrajectoryResult(False, f'point {k}: reaching {names[j]} '
                                                   f'{q[j]:.4f} from {previous_q[j]:.4f} needs '
                                                   'a time_from_start > 0')
                continue
            dt = when - previous_abs
            speed = step / dt
            if np.any(speed > vmax + LIMIT_TOLERANCE):
                j = int(np.argmax(speed - vmax))
                return TrajectoryResult(
                    False, f'point {k}: {names[j]} would move {step[j]:.4f} in {dt:.3f} s '
                           f'({speed[j]:.3f}/s), above its velocity limit {vmax[j]:.3f}/s')
            previous_abs, previous_q = when, q
        end = start + request.points[-1].time_from_start
        if end < now:
            return TrajectoryResult(False, f'trajectory ends at {end:.3f} s, before now '
                                           f'({now:.3f} s): its start stamp is too old')
        return TrajectoryResult(True)

    def set_trajectory(self, request: TrajectoryRequest, now: float,
                       current: Optional[Vector] = None) -> TrajectoryResult:
        """Validate and, if valid, follow ``request`` from the desired state at ``now``.

        A start stamp in the future holds the desired position until then; points already in
        the past (an old stamp) are skipped and the motion goes to the first point ahead.
        """
        result = self.validate(request, now, current)
        if not result.accepted:
            return result
        state = self.sample(now)
        n = len(self.joint_names)
        idx = [self._index[name] for name in request.joint_names]
        start = now if request.start_time is None else request.start_time
        t_start = max(now, start)
        # Full-width waypoints: joints left out hold their current desired position.
        pos = np.tile(state.positions, (len(request.points), 1))
        vel = np.zeros_like(pos)
        acc = np.zeros_like(pos)
        given_vel = bool(request.points[0].velocities)
        given_acc = given_vel and bool(request.points[0].accelerations)
        for k, p in enumerate(request.points):
            pos[k, idx] = p.positions
            if given_vel:
                vel[k, idx] = p.velocities
            if given_acc:
                acc[k, idx] = p.accelerations
        ahead = [k for k, p in enumerate(request.points) if start + p.time_from_start > t_start]
        moving = t_start == now
        knots_t = np.array([t_start] + [start + request.points[k].time_from_start
                                        for k in ahead])
        knots_q = np.vstack([state.positions] + [pos[k] for k in ahead])
        knots_v = np.vstack([state.velocities if moving else np.zeros(n)]
                            + [vel[k] for k in ahead])
        knots_a = np.vstack([state.accelerations if moving else np.zeros(n)]
                            + [acc[k] for k in ahead])
        if not given_vel and len(knots_t) > 1:
            knots_v[1:] = _monotone_slopes(knots_t, knots_q)[1:]
            knots_v[-1] = 0.0
        with np.errstate(all='ignore'):      # (overflows are found and refused below)
            segments = [_Segment(knots_t[k], knots_t[k + 1],
                                 _poly(knots_t[k + 1] - knots_t[k], knots_q[k], knots_v[k],
                                       knots_a[k] if given_acc else None, knots_q[k + 1],
                                       knots_v[k + 1], knots_a[k + 1] if given_acc else None))
                        for k in range(len(knots_t) - 1)]
        problem = self._interpolation_problem(segments, [-1] + ahead)
        if problem:
            return TrajectoryResult(False, problem)
        self._hold = pos[-1].copy()
        self._active = _Active(segments, float(knots_t[-1]))
        return result

    def _interpolation_problem(self, segments: List[_Segment], points: List[int]) -> str:
        """Why the interpolated reference cannot be followed ('' if it can): not finite, or
        outside the position limits by more than INTERPOLATION_MARGIN of a joint's range.
        ``points[k]`` is the request's index of knot k (-1: where the motion starts)."""
        if not segments:
            return ''
        coeffs = np.stack([seg.coeffs for seg in segments])                  # (m, 6, n)
        span = np.array([seg.t1 - seg.t0 for seg in segments])
        s = span[:, None] * np.linspace(0.0, 1.0, CHECK_SAMPLES)[None, :]   # (m, k)
        powers = s[:, :, None] ** np.arange(6)[None, None, :]               # (m, k, 6)
        with np.errstate(all='ignore'):
            q = np.einsum('mki,min->mkn', powers, coeffs)                   # (m, k, n)
        bad = ~np.isfinite(coeffs).all(axis=(1, 2)) | ~np.isfinite(q).all(axis=(1, 2))
        if np.any(bad):
            m = int(np.argmax(bad))
            return (f'the motion from {_knot(points[m])} to {_knot(points[m + 1])} overflows '
                    'floating point (are its velocities or accelerations finite but huge?)')
        lower, upper = self.limits.lower, self.limits.upper
        margin = INTERPOLATION_MARGIN * np.where(np.isfinite(upper - lower), upper - lower, 0.0)
        out = (q < (lower - margin)) | (q > (upper + margin))
        if np.any(out):
            m, _, j = (int(i) for i in np.argwhere(out)[0])
            reach = q[m, :, j].min() if q[m, :, j].min() < lower[j] else q[m, :, j].max()
            return (f'between {_knot(points[m])} and {_knot(points[m + 1])} the interpolated '
                    f'{self.joint_names[j]} reaches {reach:.4g}, outside its limits '
                    f'[{lower[j]:.4f}, {upper[j]:.4f}] (do the given velocities or '
                    'accelerations overshoot?)')
        return ''

    def sample(self, t: float) -> DesiredState:
        """The desired state at time ``t``."""
        n = len(self.joint_names)
        segments = self._active.segments
        if segments and t < self._active.end_time:
            if t < segments[0].t0:
                first = segments[0]
                return DesiredState(first.coeffs[0].copy(), np.zeros(n), np.zeros(n))
            for seg in segments:
                if t <= seg.t1:
                    return _evaluate(seg, t)
        return DesiredState(self._hold.copy(), np.zeros(n), np.zeros(n))

    def finished(self, t: float) -> bool:
        return not self._active.segments or t >= self._active.end_time

    @property
    def end_time(self) -> float:
        """When the trajectory being followed ends (-inf when holding)."""
        return self._active.end_time


def _knot(k: int) -> str:
    return 'the current state' if k < 0 else f'point {k}'


def _check_point(point: TrajectoryPoint, k: int, n: int) -> str:
    if len(point.positions) != n:
        return (f'point {k}: {len(point.positions)} positions for {n} joints')
    for name in ('velocities', 'accelerations', 'effort'):
        values = getattr(point, name)
        if values and len(values) != n:
            return f'point {k}: {len(values)} {name} for {n} joints'
    for name in ('positions', 'velocities', 'accelerations', 'effort'):
        values = getattr(point, name)
        if values and not all(math.isfinite(v) for v in values):
            return f'point {k}: non-finite {name} {list(values)}'
    if not math.isfinite(point.time_from_start):
        return f'point {k}: non-finite time_from_start'
    return ''


def _monotone_slopes(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes at the knots: zero at local extrema, so no overshoot."""
    h = np.diff(t)[:, None]
    delta = np.diff(q, axis=0) / h
    v = np.zeros_like(q)
    for k in range(1, len(t) - 1):
        d0, d1 = delta[k - 1], delta[k]
        w0 = 2 * h[k] + h[k - 1]
        w1 = h[k] + 2 * h[k - 1]
        same = d0 * d1 > 0.0
        with np.errstate(divide='ignore', invalid='ignore'):
            harmonic = (w0 + w1) / (w0 / d0 + w1 / d1)
        v[k] = np.where(same, harmonic, 0.0)
    return v


def _poly(T: float, q0: Vector, v0: Vector, a0: Optional[Vector], q1: Vector, v1: Vector,
          a1: Optional[Vector]) -> np.ndarray:
    """Coefficients (6, n) of the cubic (a0, a1 None) or quintic joining two states."""
    q0, v0, q1, v1 = (np.asarray(x, float) for x in (q0, v0, q1, v1))
    c = np.zeros((6, len(q0)))
    c[0], c[1] = q0, v0
    if a0 is None:
        c[2] = (3 * (q1 - q0) - (2 * v0 + v1) * T) / T ** 2
        c[3] = (-2 * (q1 - q0) + (v0 + v1) * T) / T ** 3
        return c
    assert a1 is not None               # (a quintic has both ends' accelerations)
    a0, a1 = np.asarray(a0, float), np.asarray(a1, float)
    c[2] = a0 / 2
    dq = q1 - q0 - v0 * T - a0 * T ** 2 / 2
    dv = v1 - v0 - a0 * T
    da = a1 - a0
    c[3] = (20 * dq - 8 * dv * T + da * T ** 2) / (2 * T ** 3)
    c[4] = (-30 * dq + 14 * dv * T - 2 * da * T ** 2) / (2 * T ** 4)
    c[5] = (12 * dq - 6 * dv * T + da * T ** 2) / (2 * T ** 5)
    return c


def _evaluate(seg: _Segment, t: float) -> DesiredState:
    s = min(max(t - seg.t0, 0.0), seg.t1 - seg.t0)
    c = seg.coeffs
    powers = np.array([s ** i for i in range(6)])
    pos = powers @ c
    vel = np.array([i * s ** (i - 1) if i else 0.0 for i in range(6)]) @ c
    acc = np.array([i * (i - 1) * s ** (i - 2) if i > 1 else 0.0 for i in range(6)]) @ c
    return DesiredState(pos, vel, acc)
