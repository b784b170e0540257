"""Time-optimal joint motions through waypoints, jerk-limited, with ruckig (no ROS).

A motion starts at rest and goes through a list of waypoints. At a waypoint the arm either comes
to rest (and may hold there) or passes through it without stopping. Each segment between two
waypoints is ruckig's time-optimal, time-synchronised profile from the state at one waypoint to
the state at the next, within the joints' velocity, acceleration and jerk limits.

Ruckig's community edition plans state to state only (its own through-waypoint planning is a
paid or cloud feature), so the velocity at a pass-through waypoint is chosen here: per joint,
the smaller of the average speeds of the rest-to-rest segments into and out of it when the joint
keeps its direction there, and zero when it turns back. The result is sampled densely with
positions, velocities and accelerations, which a joint trajectory controller interpolates
exactly (quintic per sample interval).

A waypoint may also be a state at a time: reached at exactly ``at`` (absolute), with a given
velocity and acceleration (``TooLate`` when the arm cannot be there by then). That is how an arm
meets something moving, such as a material on a running belt; a run of ``direct`` waypoints then
follows a path timed by the caller (each one sent as it is, with no profile into it).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike
from ruckig import InputParameter, Result, Ruckig, Trajectory

from controllers.arrays import Vector

SAMPLE_PERIOD_S = 0.05
# Plans stay this far inside the limits: the position motors add a small correction to the
# planned speed while they follow it, and the measured speed must stay within the limit.
LIMIT_MARGIN = 0.98
# A profile may pass a joint's position limit by this much [rad or m].
POSITION_TOLERANCE = 1e-6
# The speeds tried at a pass-through waypoint, as multiples of the first guess (the smaller of
# the average speeds of the rest-to-rest segments around it): the one that gives the shortest
# pair of segments around the waypoint is kept.
VIA_SCALES = (1.0, 0.5, 1.5, 2.0, 3.0, 4.0)
# The speed limits tried along a timed path, as fractions of the highest the joints allow.
PATH_SPEED_FRACTIONS = (1.0, 0.85, 0.7, 0.55, 0.4)


class PlanError(ValueError):
    """The waypoints or limits cannot be planned (not finite, wrong size, no profile)."""


class TooLate(PlanError):
    """A waypoint's time comes before the arm can be there (``by``: how much too early [s])."""

    def __init__(self, message: str, by: float) -> None:
        super().__init__(message)
        self.by = by


@dataclass(frozen=True)
class JointLimits:
    velocity: np.ndarray          # [rad/s] per joint
    acceleration: np.ndarray      # [rad/s^2]
    jerk: np.ndarray              # [rad/s^3]
    # The positions a profile keeps within (None: not checked). A profile through a waypoint
    # without stopping can swing past both its ends: one that leaves them is not used.
    lower: Optional[np.ndarray] = None
    upper: Optional[np.ndarray] = None

    def scaled(self, fraction: float) -> 'JointLimits':
        """The same limits with the velocity scaled (acceleration and jerk kept)."""
        if not 0.0 < fraction <= 1.0:
            raise PlanError(f'velocity scaling must be within (0, 1], got {fraction}')
        return JointLimits(np.asarray(self.velocity) * fraction, self.acceleration, self.jerk,
                           self.lower, self.upper)

    def contain(self, trajectory: Trajectory) -> bool:
        """Whether a profile keeps every joint within its position limits (if given)."""
        if self.lower is None or self.upper is None:
            return True
        return all(lo - POSITION_TOLERANCE <= e.min and e.max <= hi + POSITION_TOLERANCE
                   for e, lo, hi in zip(trajectory.position_extrema, self.lower.tolist(),
                                        self.upper.tolist()))


@dataclass(frozen=True)
class Waypoint:
    q: np.ndarray
    stop: bool = True             # the arm comes to rest here
    hold: float = 0.0             # and stays this long [s] (stop only)
    min_time: float = 0.0         # the segment into it takes at least this long [s]
    # A state to pass through: this velocity and acceleration here (not a stop) ...
    velocity: Optional[np.ndarray] = None
    acceleration: Optional[np.ndarray] = None
    at: Optional[float] = None    # ... reached at exactly this (absolute) time [s]
    direct: bool = False          # sent as it is: a sample of a path the caller timed (needs
    #                               ``at`` and ``velocity``), with no profile into it


@dataclass(frozen=True)
class Sample:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray


@dataclass(frozen=True)
class Plan:
    samples: List[Sample]         # from the start (t0, at rest) to the end (at rest)
    arrivals: List[float]         # when each waypoint is reached (before its hold) [s]

    @property
    def end(self) -> float:
        return self.samples[-1].t

    def points(self) -> List[Tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
        return [(s.t, s.q, s.v, s.a) for s in self.samples]


def _profile(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray,
             limits: JointLimits, min_time: float, a0: Optional[np.ndarray] = None,
             a1: Optional[np.ndarray] = None) -> Optional[Trajectory]:
    n = len(q0)
    otg = Ruckig(n)
    inp = InputParameter(n)
    inp.current_position, inp.current_velocity = list(q0), list(v0)
    inp.current_acceleration = [0.0] * n if a0 is None else list(a0)
    inp.target_position, inp.target_velocity = list(q1), list(v1)
    inp.target_acceleration = [0.0] * n if a1 is None else list(a1)
    inp.max_velocity = list(np.asarray(limits.velocity) * LIMIT_MARGIN)
    inp.max_acceleration = list(np.asarray(limits.acceleration) * LIMIT_MARGIN)
    inp.max_jerk = list(np.asarray(limits.jerk) * LIMIT_MARGIN)
    if min_time > 0.0:
        inp.minimum_duration = float(min_time)
    trajectory = Trajectory(n)
    try:
        result = otg.calculate(inp, trajectory)
    except Exception:               # ruckig.RuckigError: a state outside the limits
        return None
    if result != Result.Working or not limits.contain(trajectory):
        return None
    return trajectory


def rest_to_rest_time(q0: ArrayLike, q1: ArrayLike, limits: JointLimits) -> float:
    """The shortest time from rest at ``q0`` to rest at ``q1``."""
    start, goal = np.asarray(q0, float), np.asarray(q1, float)
    n = len(start)
    profile = _profile(start, np.zeros(n), goal, np.zeros(n), limits, 0.0)
    if profile is None:
        raise PlanError('no profile between the two positions')
    return float(profile.duration)


def _via_velocity(q_prev: np.ndarray, q: np.ndarray, q_next: np.ndarray,
                  limits: JointLimits) -> np.ndarray:
    d_in, d_out = q - q_prev, q_next - q
    t_in = max(rest_to_rest_time(q_prev, q, limits), 1e-6)
    t_out = max(rest_to_rest_time(q, q_next, limits), 1e-6)
    v = np.minimum(np.abs(d_in) / t_in, np.abs(d_out) / t_out) * np.sign(d_in)
    v[np.sign(d_in) != np.sign(d_out)] = 0.0
    return np.asarray(np.clip(v, -0.9 * limits.velocity, 0.9 * limits.velocity), float)


def _improve_vias(q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, qs: List[np.ndarray],
                  velocities: List[np.ndarray], accelerations: List[Optional[np.ndarray]],
                  free: List[bool], waypoints: Sequence[Waypoint], limits: JointLimits
                  ) -> None:
    """Choose, waypoint by waypoint, the speed at each pass-through waypoint (``free``) among
    VIA_SCALES times the first guess: the one with the shortest two segments around it. The
    average speeds of rest-to-rest segments are a cautious guess: a joint that keeps its
    direction through a waypoint can pass it faster, and the profile out of it is shorter then.
    A timed waypoint after it is taken at its state, as soon as the arm can be there (its
    time is what the caller asks of the arm, and the sooner it can be met the better)."""
    cap = 0.9 * np.asarray(limits.velocity, float)
    for i in range(len(qs) - 1):
        if not free[i] or waypoints[i + 1].direct:
            continue
        q_prev = qs[i - 1] if i else q0
        v_prev = velocities[i - 1] if i else v0
        guess = velocities[i]
        if not np.any(guess):
            continue
        best, best_time = guess, None
        for scale in VIA_SCALES:
            v = np.clip(guess * scale, -cap, cap)
            into = _profile(q_prev, v_prev, qs[i], v, limits, waypoints[i].min_time,
                            accelerations[i - 1] if i else a0)
            out = _profile(qs[i], v, qs[i + 1], velocities[i + 1], limits,
                           waypoints[i + 1].min_time, None, accelerations[i + 1])
            if into is None or out is None:
                continue
            total = float(into.duration) + float(out.duration)
            if best_time is None or total < best_time - 1e-6:
                best, best_time = v, total
        velocities[i] = best


def plan(q0: Vector, waypoints: Sequence[Waypoint], limits: JointLimits,
         t0: float = 0.0, period: float = SAMPLE_PERIOD_S,
         v0: Optional[Vector] = None, a0: Optional[Vector] = None) -> Plan:
    """The motion from rest at ``q0`` (or moving: velocity ``v0``, acceleration ``a0``)
    through ``waypoints`` (the last one is a stop), starting at ``t0``, sampled every
    ``period`` and at every waypoint."""
    q_prev = np.asarray(q0, float)
    n = len(q_prev)
    if not waypoints:
        raise PlanError('a motion needs at least one waypoint')
    v_given, a_given = _state(v0, n, 'start velocity'), _state(a0, n, 'start acceleration')
    v_start = np.zeros(n) if v_given is None else v_given
    a_start = np.zeros(n) if a_given is None else a_given
    qs, given_v, given_a = _checked(q_prev, waypoints, limits)
    stops = [w.stop and given_v[i] is None for i, w in enumerate(waypoints)]
    stops[-1] = True
    velocities: List[np.ndarray] = []
    for i, q in enumerate(qs):
        given = given_v[i]
        if given is not None:
            velocities.append(given)
        elif stops[i]:
            velocities.append(np.zeros(n))
        else:
            velocities.append(_via_velocity(qs[i - 1] if i else q_prev, q, qs[i + 1], limits))
    free = [given_v[i] is None and not stops[i] for i in range(len(qs))]
    _improve_vias(q_prev, v_start, a_start, qs, velocities, given_a, free, waypoints, limits)
    samples = [Sample(t0, q_prev.copy(), v_start.copy(), a_start.copy())]
    arrivals = []
    t, v_prev, a_prev = t0, v_start, a_start
    for i, w in enumerate(waypoints):
        a_given_here = given_a[i]
        a_here = a_given_here if a_given_here is not None else np.zeros(n)
        if w.direct:
            t = _direct(samples, i, w, t, qs[i], velocities[i], a_here)
            arrivals.append(t)
        else:
            min_time = w.min_time if w.at is None else max(w.min_time, w.at - t)
            if w.at is not None and w.at - t < -1e-9:
                raise TooLate(f'waypoint {i} is due at {w.at:.3f} s, before the motion gets '
                              f'to it ({t:.3f} s)', t - w.at)
            profile = _profile(q_prev, v_prev, qs[i], velocities[i], limits, min_time, a_prev,
                               a_here)
            if profile is None and np.any(velocities[i]) and given_v[i] is None:
                velocities[i] = np.zeros(n)   # pass-through not reachable from here: stop there
                profile = _profile(q_prev, v_prev, qs[i], velocities[i], limits, min_time,
                                   a_prev)
            if profile is None:
                raise PlanError(f'no profile to waypoint {i}')
            t = _sampled(samples, i, w, t, profile, period, qs[i], velocities[i], a_here)
            arrivals.append(t)
            if stops[i] and w.hold > 0.0:
                t += w.hold
                samples.append(Sample(t, qs[i].copy(), np.zeros(n), np.zeros(n)))
        q_prev, v_prev, a_prev = qs[i], velocities[i], a_here
    return Plan(samples, arrivals)


def brake(q: Vector, v: Vector, a: Vector, limits: JointLimits, t: float) -> Plan:
    """From a moving state (``q``, ``v``, ``a`` at ``t``) to rest as soon as the joints allow,
    where each comes to rest braking at its acceleration limit, reached at its jerk limit
    (planned back to ``q``, or short of that, the joints would overshoot and return)."""
    q0, v0 = np.asarray(q, float), np.asarray(v, float)
    acc, jerk = limits.acceleration, limits.jerk
    stop = q0 + v0 * (np.abs(v0) / (2.0 * acc) + acc / (2.0 * jerk))
    return plan(q0, [Waypoint(stop)], limits, t, v0=v0, a0=np.asarray(a, float))


def _checked(q0: np.ndarray, waypoints: Sequence[Waypoint], limits: JointLimits
             ) -> Tuple[List[np.ndarray], List[Optional[np.ndarray]],
                        List[Optional[np.ndarray]]]:
    """The waypoints' positions, given velocities and given accelerations, once the limits
    and the waypoints are found sound (PlanError says why not)."""
    n = len(q0)
    for name in ('velocity', 'acceleration', 'jerk'):
        limit_values = np.asarray(getattr(limits, name), float)
        if (limit_values.shape != (n,) or not np.all(np.isfinite(limit_values))
                or np.any(limit_values <= 0.0)):
            raise PlanError(f'{name} limits must be {n} positive finite values')
    qs = [np.asarray(w.q, float) for w in waypoints]
    if any(q.shape != (n,) or not np.all(np.isfinite(q)) for q in qs) or not np.all(
            np.isfinite(q0)):
        raise PlanError(f'every waypoint must be {n} finite joint positions')
    given_v = [_state(w.velocity, n, 'velocity') for w in waypoints]
    given_a = [_state(w.acceleration, n, 'acceleration') for w in waypoints]
    for i, w in enumerate(waypoints):
        if w.at is not None and not np.isfinite(w.at):
            raise PlanError(f'waypoint {i}: its time must be finite')
        if w.direct and (w.at is None or given_v[i] is None):
            raise PlanError(f'waypoint {i}: a direct waypoint needs a time and a velocity')
        for name, value, limit in (('velocity', given_v[i], limits.velocity),
                                   ('acceleration', given_a[i], limits.acceleration)):
            if value is not None and np.any(np.abs(value) > np.asarray(limit) * LIMIT_MARGIN):
                j = int(np.argmax(np.abs(value) / np.asarray(limit)))
                raise PlanError(f'waypoint {i}: joint {j + 1} {name} {value[j]:.3f} is beyond '
                                f'its limit {limit[j] * LIMIT_MARGIN:.3f}')
    last_v, last_a = given_v[-1], given_a[-1]
    if last_v is not None and np.any(last_v) or last_a is not None and np.any(last_a):
        raise PlanError('a motion ends at rest: the last waypoint cannot have a velocity')
    return qs, given_v, given_a


def _direct(samples: List[Sample], i: int, w: Waypoint, t: float, q: np.ndarray,
            v: np.ndarray, a: np.ndarray) -> float:
    """A direct waypoint: the arm is there at its time, as given; returns that time."""
    assert w.at is not None             # (checked: a direct waypoint has one)
    if w.at <= t + 1e-9:
        raise PlanError(f'waypoint {i}: a direct waypoint must come after the one before it '
                        f'({w.at:.3f} s <= {t:.3f} s)')
    samples.append(Sample(float(w.at), q.copy(), v.copy(), a.copy()))
    return float(w.at)


def _sampled(samples: List[Sample], i: int, w: Waypoint, t: float, profile: Trajectory,
             period: float, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> float:
    """The profile from time ``t`` to waypoint ``i``, sampled every ``period`` and ending
    exactly at the waypoint; returns the arrival time."""
    duration = float(profile.duration)
    if w.at is not None and duration > w.at - t + 1e-6:
        raise TooLate(f'waypoint {i} is due at {w.at:.3f} s; the arm can be there at '
                      f'{t + duration:.3f} s at the earliest', t + duration - w.at)
    if duration <= 1e-9:         # (a waypoint where the arm already is adds no samples)
        return t
    steps = max(1, int(np.ceil(duration / period - 1e-9)))
    for k in range(1, steps + 1):
        tau = duration * k / steps
        p, vel, acc = profile.at_time(tau)
        samples.append(Sample(t + tau, np.asarray(p, float), np.asarray(vel, float),
                              np.asarray(acc, float)))
    t += duration
    samples[-1] = Sample(t, q.copy(), v.copy(), a.copy())
    return t


def timed_path(qs: Sequence[Vector], limits: JointLimits, t0: float,
               period: float = SAMPLE_PERIOD_S, end_speed: float = 0.0,
               min_time: float = 0.0) -> List[Waypoint]:
    """A path the tool must keep to (a straight line, say), given as joint positions at evenly
    spaced points along it, timed as ``direct`` waypoints after ``t0``: from rest at
    ``qs[0]`` at ``t0`` along the path, time-optimally within limits on the path's speed that
    keep every joint within its own, and in ``min_time`` at least. It ends at ``qs[-1]`` at
    rest, or moving on at ``end_speed`` (a fraction of the path's top speed) to go on to a
    next waypoint. The path is a cubic in its length fitted to the points, through its ends:
    a tool's straight line is smooth in joint space, and the youBot's 6 cm lift off its plate
    keeps to its points within 0.05 mm."""
    points = np.asarray(qs, float)
    if points.ndim != 2 or len(points) < 2 or not np.all(np.isfinite(points)):
        raise PlanError('a timed path needs two or more points of finite joint positions')
    if not 0.0 <= end_speed <= 1.0:
        raise PlanError(f'the end speed is a fraction within [0, 1], got {end_speed}')
    coef = _path_cubic(points)
    profile = _path_profile(coef, limits, end_speed, min_time)
    duration = float(profile.duration)
    steps = max(1, int(np.ceil(duration / period - 1e-9)))
    waypoints = []
    for k in range(1, steps + 1):
        t = duration * k / steps
        (s,), (s1,), (s2,) = profile.at_time(t)
        q, q1, q2 = (np.polynomial.polynomial.polyval(min(max(s, 0.0), 1.0), c)
                     for c in coef[:3])
        v, a = q1 * s1, q2 * s1**2 + q1 * s2
        if k == steps and end_speed == 0.0:
            v, a = np.zeros_like(v), np.zeros_like(a)        # (zero but for rounding)
        waypoints.append(Waypoint(q, velocity=v, acceleration=a, at=t0 + t, direct=True))
    return waypoints


def _path_cubic(points: np.ndarray) -> List[np.ndarray]:
    """A cubic in the path's length fraction fitted to its points, corrected to pass through
    its ends exactly: its coefficients and those of its first three derivatives."""
    fit = np.polynomial.polynomial.polyfit(np.linspace(0.0, 1.0, len(points)), points,
                                           min(len(points) - 1, 3))
    if len(fit) < 2:
        fit = np.vstack([fit, np.zeros_like(fit)])
    first = points[0] - fit[0]
    last = points[-1] - np.polynomial.polynomial.polyval(1.0, fit).T
    fit[0] += first
    fit[1] += last - first
    coef = [fit]
    for _ in range(3):
        coef.append(np.polynomial.polynomial.polyder(coef[-1]))
    return coef


def _path_profile(coef: Sequence[np.ndarray], limits: JointLimits, end_speed: float,
                  min_time: float) -> Trajectory:
    """The time-optimal profile of the path's length fraction (ruckig, one degree of
    freedom): from rest at 0 to 1, ending at ``end_speed``, within limits that keep every
    joint within its own."""
    grid = np.linspace(0.0, 1.0, 201)
    # The largest |dq/ds|, |d2q/ds2| and |d3q/ds3| of each joint along the path (s: its length
    # fraction). With them, limits on the path's speed s', acceleration s'' and jerk s''' keep
    # every joint within its own: dq/dt = q' s', d2q/dt2 = q'' s'^2 + q' s'', and
    # d3q/dt3 = q''' s'^3 + 3 q'' s' s'' + q' s'''. A higher speed limit leaves less room for
    # the acceleration: of a few speed limits, the one with the shortest profile is kept.
    d1, d2, d3 = (np.max(np.abs(np.polynomial.polynomial.polyval(grid, c).T), 0) + 1e-12
                  for c in coef[1:])
    v_lim, a_lim, j_lim = (np.asarray(getattr(limits, k), float) * LIMIT_MARGIN
                           for k in ('velocity', 'acceleration', 'jerk'))
    top = min(np.min(v_lim / d1), np.min(np.sqrt(0.9 * a_lim / d2)),
              np.min(np.cbrt(0.9 * j_lim / d3)))
    profile = None
    for fraction in PATH_SPEED_FRACTIONS:
        ds = fraction * top
        dds = np.min((a_lim - d2 * ds**2) / d1)
        ddds = np.min((j_lim - d3 * ds**3 - 3 * d2 * ds * dds) / d1)
        if not (dds > 0.0 and ddds > 0.0):
            continue
        otg, inp, candidate = Ruckig(1), InputParameter(1), Trajectory(1)
        inp.current_position, inp.current_velocity = [0.0], [0.0]
        inp.current_acceleration = [0.0]
        inp.target_position, inp.target_velocity = [1.0], [end_speed * ds]
        inp.target_acceleration = [0.0]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [ds], [dds], [ddds]
        if min_time > 0.0:
            inp.minimum_duration = float(min_time)
        try:
            if otg.calculate(inp, candidate) != Result.Working:
                continue
        except Exception:           # ruckig.RuckigError
            continue
        if profile is None or candidate.duration < profile.duration:
            profile = candidate
    if profile is None:
        raise PlanError('no speed along the path keeps the joints within their limits')
    return profile


def _state(value: Optional[ArrayLike], n: int, what: str) -> Optional[np.ndarray]:
    if value is None:
        return None
    out = np.asarray(value, float)
    if out.shape != (n,) or not np.all(np.isfinite(out)):
        raise PlanError(f'a waypoint {what} must be {n} finite values')
    return out
