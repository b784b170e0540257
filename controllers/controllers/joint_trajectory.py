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

import bisect
import math
from dataclasses import dataclass, field, replace
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


def slowed(request: TrajectoryRequest, scale: float) -> TrajectoryRequest:
    """The same path taken ``scale`` times as fast (< 1: a slower arm): each point's time from
    the start divided by ``scale``, its velocities times ``scale``, accelerations times its
    square. A trajectory for an arm that cannot keep its nominal speed."""
    if not (math.isfinite(scale) and scale > 0.0):
        raise ValueError(f'a speed scale must be finite and > 0, got {scale}')
    return replace(request, points=tuple(
        replace(pt, time_from_start=pt.time_from_start / scale,
                velocities=tuple(v * scale for v in pt.velocities),
                accelerations=tuple(a * scale * scale for a in pt.accelerations))
        for pt in request.points))


@dataclass
class TrajectoryResult:
    accepted: bool
    reason: str = ''


class _Segments:
    """Polynomial segments between knots: segment k runs from knots[k] to knots[k + 1], its
    position a polynomial in (t - knots[k]) with coefficients coeffs[k] (6 x n, lowest order
    first)."""

    def __init__(self, knots: np.ndarray, coeffs: np.ndarray) -> None:
        self.knots = knots
        self.knot_list = knots.tolist()        # (for bisect, at every step)
        self.coeffs = coeffs

    def __len__(self) -> int:
        return len(self.coeffs)


@dataclass
class DesiredState:
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


@dataclass
class _Active:
    segments: _Segments = field(default_factory=lambda: _Segments(np.zeros(1),
                                                                  np.zeros((0, 6, 0))))
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
        return bool(len(self._active.segments))

    def hold(self, positions: Vector) -> None:
        """Stop following and hold these positions."""
        n = len(self.joint_names)
        self._hold = np.array(positions, float).reshape(n)
        self._active = _Active()

    def validate(self, request: TrajectoryRequest, now: float,
                 current: Optional[Vector] = None) -> TrajectoryResult:
        """Check a trajectory; ``current`` is where the joints are (default: desired).

        The points are screened together (a 10,000-point trajectory took 0.9 s point by point,
        with the simulator's clock stopped); the first point the screen finds wrong is then
        checked alone, which says why."""
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
        points = request.points
        if not points:
            return TrajectoryResult(False, 'empty trajectory: no points')
        for name in ('velocities', 'accelerations'):
            given = [bool(getattr(p, name)) for p in points]
            if any(given) and not all(given):
                return TrajectoryResult(False, f'{name} given for some points but not all')
        check = _PointCheck(self, request, now, current)
        first = check.screen()
        if first is not None:
            reason = check.explain(first)
            if reason:
                return TrajectoryResult(False, reason)
        end = check.start + points[-1].time_from_start
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
        points = request.points
        idx = [self._index[name] for name in request.joint_names]
        start = now if request.start_time is None else request.start_time
        t_start = max(now, start)
        given_vel = bool(points[0].velocities)
        given_acc = given_vel and bool(points[0].accelerations)
        times = np.array([start + p.time_from_start for p in points])
        ahead = np.flatnonzero(times > t_start)
        moving = t_start == now
        # Full-width knots: joints left out hold their current desired position.
        knots_t = np.concatenate([[t_start], times[ahead]])
        knots_q = np.tile(state.positions, (len(knots_t), 1))
        knots_v = np.zeros_like(knots_q)
        knots_a = np.zeros_like(knots_q)
        knots_v[0] = state.velocities if moving else 0.0
        knots_a[0] = state.accelerations if moving else 0.0
        chosen = [points[k] for k in ahead]
        if chosen:
            knots_q[1:, idx] = [p.positions for p in chosen]
            if given_vel:
                knots_v[1:, idx] = [p.velocities for p in chosen]
            if given_acc:
                knots_a[1:, idx] = [p.accelerations for p in chosen]
        if not given_vel and len(knots_t) > 1:
            knots_v[1:] = _monotone_slopes(knots_t, knots_q)[1:]
            knots_v[-1] = 0.0
        with np.errstate(all='ignore'):      # (overflows are found and refused below)
            coeffs = _poly(np.diff(knots_t), knots_q[:-1], knots_v[:-1],
                           knots_a[:-1] if given_acc else None, knots_q[1:], knots_v[1:],
                           knots_a[1:] if given_acc else None)
        segments = _Segments(knots_t, coeffs)
        problem = self._interpolation_problem(segments, [-1] + ahead.tolist())
        if problem:
            return TrajectoryResult(False, problem)
        last = state.positions.copy()
        last[idx] = points[-1].positions
        self._hold = last
        self._active = _Active(segments, float(knots_t[-1]))
        return result

    def _interpolation_problem(self, segments: '_Segments', points: List[int]) -> str:
        """Why the interpolated reference cannot be followed ('' if it can): not finite, or
        outside the position limits by more than INTERPOLATION_MARGIN of a joint's range.
        ``points[k]`` is the request's index of knot k (-1: where the motion starts)."""
        if not len(segments):
            return ''
        coeffs = segments.coeffs                                             # (m, 6, n)
        span = np.diff(segments.knots)
        s = span[:, None] * np.linspace(0.0, 1.0, CHECK_SAMPLES)[None, :]   # (m, k)
        with np.errstate(all='ignore'):
            powers = s[:, :, None] ** np.arange(6)[None, None, :]           # (m, k, 6)
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
        if len(segments) and t < self._active.end_time:
            knots = segments.knot_list
            if t < knots[0]:
                return DesiredState(segments.coeffs[0, 0].copy(), np.zeros(n), np.zeros(n))
            # The first segment that ends at or after t.
            k = min(bisect.bisect_left(knots, t, 1) - 1, len(segments) - 1)
            return _evaluate(knots[k], knots[k + 1], segments.coeffs[k], t)
        return DesiredState(self._hold.copy(), np.zeros(n), np.zeros(n))

    def finished(self, t: float) -> bool:
        return not len(self._active.segments) or t >= self._active.end_time

    @property
    def end_time(self) -> float:
        """When the trajectory being followed ends (-inf when holding)."""
        return self._active.end_time


class _PointCheck:
    """The per-point rules of :meth:`TrajectoryFollower.validate`: :meth:`screen` applies them
    to all points at once and finds the first that breaks one; :meth:`explain` applies them
    to one point, in order, and says which it breaks."""

    def __init__(self, follower: TrajectoryFollower, request: TrajectoryRequest, now: float,
                 current: Optional[Vector]) -> None:
        self.request, self.now = request, now
        self.names = request.joint_names
        idx = [follower._index[n] for n in self.names]
        limits = follower.limits
        self.lower, self.upper = limits.lower[idx], limits.upper[idx]
        self.vmax = limits.velocity[idx]
        self.amax = np.asarray(limits.acceleration, float)[idx]
        if current is None:
            current = follower.sample(now).positions
        self.current = np.asarray(current, float)[idx]
        self.start = now if request.start_time is None else request.start_time
        self.t_start = max(now, self.start)

    def screen(self) -> Optional[int]:
        """The index of the first point that breaks a rule, None if none does."""
        points, n = self.request.points, len(self.names)
        for name in ('positions', 'velocities', 'accelerations', 'effort'):
            sizes = {len(getattr(p, name)) for p in points}
            if not sizes <= ({n} if name == 'positions' else {0, n}):
                return next(k for k, p in enumerate(points) if _check_point(p, k, n))
        t = np.array([p.time_from_start for p in points], float)
        q = np.array([p.positions for p in points], float).reshape(len(points), n)
        bad = ~np.isfinite(t) | ~np.isfinite(q).all(axis=1)
        v = a = None
        if points[0].velocities:
            v = np.array([p.velocities for p in points], float)
            bad |= ~np.isfinite(v).all(axis=1)
        if points[0].accelerations:
            a = np.array([p.accelerations for p in points], float)
            bad |= ~np.isfinite(a).all(axis=1)
        if any(p.effort for p in points):
            bad |= np.array([not all(math.isfinite(e) for e in p.effort) for p in points])
        with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
            bad |= t < 0.0
            bad[1:] |= t[1:] <= t[:-1]
            bad |= ((q < self.lower - LIMIT_TOLERANCE)
                    | (q > self.upper + LIMIT_TOLERANCE)).any(axis=1)
            if v is not None:
                bad |= (np.abs(v) > self.vmax + LIMIT_TOLERANCE).any(axis=1)
            if a is not None:
                bad |= (np.abs(a) > self.amax * (1.0 + 1e-9)).any(axis=1)
            when = self.start + t
            at_start = (when >= self.now) & (when <= self.t_start)
            bad |= at_start & (np.abs(q - self.current) > START_TOLERANCE).any(axis=1)
            ahead = np.flatnonzero(when > self.t_start)
            if len(ahead):
                before_t = np.concatenate([[self.t_start], when[ahead[:-1]]])
                before_q = np.vstack([self.current[None, :], q[ahead[:-1]]])
                speed = np.abs(q[ahead] - before_q) / (when[ahead] - before_t)[:, None]
                bad[ahead] |= (speed > self.vmax + LIMIT_TOLERANCE).any(axis=1)
        return int(np.argmax(bad)) if np.any(bad) else None

    def explain(self, first: int) -> str:
        """Why point ``first`` (or a later one) breaks a rule: the points before it are
        followed to know where the motion stands, then each from ``first`` is checked."""
        points = self.request.points
        previous_abs, previous_q = self.t_start, self.current
        for k in range(first):
            when = self.start + points[k].time_from_start
            if when > self.t_start:
                previous_abs, previous_q = when, np.asarray(points[k].positions, float)
        previous_t = points[first - 1].time_from_start if first else -math.inf
        for k in range(first, len(points)):
            reason, previous_t, previous_abs, previous_q = self._point(
                k, previous_t, previous_abs, previous_q)
            if reason:
                return reason
        return ''

    def _point(self, k: int, previous_t: float, previous_abs: float,
               previous_q: np.ndarray) -> Tuple[str, float, float, np.ndarray]:
        point, names = self.request.points[k], self.names
        keep = ('', previous_t, previous_abs, previous_q)
        reason = _check_point(point, k, len(names))
        if reason:
            return (reason,) + keep[1:]
        t = point.time_from_start
        if t < 0.0:
            return (f'point {k}: time_from_start {t:g} s is negative',) + keep[1:]
        if t <= previous_t:
            return (f'point {k}: time_from_start {t:g} s is not after point {k - 1}\'s '
                    f'{previous_t:g} s',) + keep[1:]
        previous_t = t
        q = np.asarray(point.positions, float)
        lower, upper = self.lower, self.upper
        out = (q < lower - LIMIT_TOLERANCE) | (q > upper + LIMIT_TOLERANCE)
        if np.any(out):
            j = int(np.argmax(out))
            return (f'point {k}: {names[j]} target {q[j]:.4f} is outside its limits '
                    f'[{lower[j]:.4f}, {upper[j]:.4f}]',) + keep[1:]
        vmax, amax = self.vmax, self.amax
        if point.velocities:
            v = np.abs(np.asarray(point.velocities, float))
            if np.any(v > vmax + LIMIT_TOLERANCE):
                j = int(np.argmax(v - vmax))
                return (f'point {k}: {names[j]} velocity {v[j]:.4f} exceeds its limit '
                        f'{vmax[j]:.4f}',) + keep[1:]
        if point.accelerations:
            a = np.abs(np.asarray(point.accelerations, float))
            if np.any(a > amax * (1.0 + 1e-9)):
                j = int(np.argmax(a - amax))
                return (f'point {k}: {names[j]} acceleration {a[j]:.4g} exceeds its limit '
                        f'{amax[j]:.4g}',) + keep[1:]
        when = self.start + t
        if when < self.now:         # already past (an old stamp): skipped when following
            return '', previous_t, previous_abs, previous_q
        step = np.abs(q - previous_q)
        if when <= self.t_start:
            if np.any(step > START_TOLERANCE):
                j = int(np.argmax(step))
                return (f'point {k}: reaching {names[j]} {q[j]:.4f} from '
                        f'{previous_q[j]:.4f} needs a time_from_start > 0',) + keep[1:]
            return '', previous_t, previous_abs, previous_q
        dt = when - previous_abs
        speed = step / dt
        if np.any(speed > vmax + LIMIT_TOLERANCE):
            j = int(np.argmax(speed - vmax))
            return (f'point {k}: {names[j]} would move {step[j]:.4f} in {dt:.3f} s '
                    f'({speed[j]:.3f}/s), above its velocity limit {vmax[j]:.3f}/s',) + keep[1:]
        return '', previous_t, when, q


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
    v = np.zeros_like(q)
    # (Knots a hair apart overflow here; what that makes of the motion is refused after.)
    with np.errstate(all='ignore'):
        h = np.diff(t)[:, None]
        delta = np.diff(q, axis=0) / h
        if len(t) > 2:
            d0, d1 = delta[:-1], delta[1:]
            h0, h1 = h[:-1], h[1:]
            w0 = 2 * h1 + h0
            w1 = h1 + 2 * h0
            harmonic = (w0 + w1) / (w0 / d0 + w1 / d1)
            v[1:-1] = np.where(d0 * d1 > 0.0, harmonic, 0.0)
    return v


def _poly(T: np.ndarray, q0: np.ndarray, v0: np.ndarray, a0: Optional[np.ndarray],
          q1: np.ndarray, v1: np.ndarray, a1: Optional[np.ndarray]) -> np.ndarray:
    """Coefficients (m, 6, n) of the cubics (a0, a1 None) or quintics joining m pairs of
    states (m x n each) over durations T (m)."""
    # Powers of T as Python floats: C's pow(), as a scalar computed them, whatever numpy's
    # vectorised power does (so a trajectory is interpolated the same to the last bit).
    T1, T2, T3, T4, T5 = (np.array([float(x) ** i for x in T.tolist()])[:, None]
                          for i in range(1, 6))
    c = np.zeros((len(T), 6, q0.shape[1]))
    c[:, 0], c[:, 1] = q0, v0
    if a0 is None:
        c[:, 2] = (3 * (q1 - q0) - (2 * v0 + v1) * T1) / T2
        c[:, 3] = (-2 * (q1 - q0) + (v0 + v1) * T1) / T3
        return c
    assert a1 is not None               # (a quintic has both ends' accelerations)
    c[:, 2] = a0 / 2
    dq = q1 - q0 - v0 * T1 - a0 * T2 / 2
    dv = v1 - v0 - a0 * T1
    da = a1 - a0
    c[:, 3] = (20 * dq - 8 * dv * T1 + da * T2) / (2 * T3)
    c[:, 4] = (-30 * dq + 14 * dv * T1 - 2 * da * T2) / (2 * T4)
    c[:, 5] = (12 * dq - 6 * dv * T1 + da * T2) / (2 * T5)
    return c


def _evaluate(t0: float, t1: float, c: np.ndarray, t: float) -> DesiredState:
    s = min(max(t - t0, 0.0), t1 - t0)
    powers = np.array([s ** i for i in range(6)])
    pos = powers @ c
    vel = np.array([i * s ** (i - 1) if i else 0.0 for i in range(6)]) @ c
    acc = np.array([i * (i - 1) * s ** (i - 2) if i > 1 else 0.0 for i in range(6)]) @ c
    return DesiredState(pos, vel, acc)
