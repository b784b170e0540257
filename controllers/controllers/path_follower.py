"""A holonomic base following a dummy that moves along a Bezier path, with a PD law on its pose.

The paper's scheme (its section 4.2): the dummy moves along the path at the profile's speed; the
robot takes the dummy's velocity as feed-forward and corrects its pose error with proportional
and derivative terms (the derivative of the error is the dummy's velocity minus the robot's, so
no numerical differentiation of a noisy pose). The command is a body twist (vx, vy, wz) for
``cmd_vel``, saturated to the base's limits.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Dict, List, Optional, Tuple

import numpy as np

from controllers.arrays import Vector
from controllers.bezier import BezierPath, MotionProfile, wrap_angle


@dataclass(frozen=True)
class PDGains:
    kp_xy: float = 2.0           # [1/s]
    kd_xy: float = 0.3           # [-]
    kp_yaw: float = 2.5          # [1/s]
    kd_yaw: float = 0.2          # [-]
    max_speed: float = 0.5       # [m/s] each of vx, vy
    max_turn: float = 1.0        # [rad/s]


@dataclass(frozen=True)
class FollowStatus:
    command: Tuple[float, float, float]     # body twist (vx, vy, wz)
    dummy: Tuple[float, float, float]       # the dummy's pose
    position_error: float                   # [m]
    yaw_error: float                        # [rad]
    finished: bool                          # dummy at the end and the robot settled on it


@dataclass(frozen=True)
class TurnLimits:
    """The dummy's heading profile in time, for a holonomic base: its rate and acceleration."""
    rate: float = 1.2            # [rad/s]
    accel: float = 1.5           # [rad/s^2]


class PathFollower:
    """Follows one path, started at ``start_time``; call ``update`` every control period.

    Without ``turn`` the dummy's heading is the path's (the key poses' headings, blended along
    each segment), and a turn as fast as the travel along the path. With ``turn`` (a holonomic
    base: its heading is free of its direction of travel) the heading goes from the first key
    pose's to the last's (the way round the key poses turn) on a profile in time of its own,
    within the limits; the travel and the turn then take the same time, the slower one's, the
    other stretched to match, so that both start and end together, and the turn is slowest at
    both ends, where the base stands close to things."""

    def __init__(self, path: BezierPath, start_time: float, max_speed: float = 0.35,
                 max_accel: float = 0.4, gains: PDGains = PDGains(),
                 position_tolerance: float = 0.01, yaw_tolerance: float = 0.02,
                 turn: Optional[TurnLimits] = None) -> None:
        self.path, self.start_time, self.gains = path, start_time, gains
        self.profile = MotionProfile(path.length, max_speed, max_accel)
        self.position_tolerance, self.yaw_tolerance = position_tolerance, yaw_tolerance
        self._turn: Optional[MotionProfile] = None
        self._yaw0, self._sweep = float(path.key_poses[0][2]), 0.0
        if turn is not None:
            self._sweep = path.heading_sweep
            spin = MotionProfile(abs(self._sweep), turn.rate, turn.accel)
            duration = max(spin.duration, self.profile.duration)
            self.profile = MotionProfile.lasting(path.length, duration, max_speed, max_accel)
            self._turn = MotionProfile.lasting(abs(self._sweep), duration, turn.rate,
                                               turn.accel)

    @property
    def end_time(self) -> float:
        return self.start_time + self.profile.duration

    def poses(self, since: float, period: float = 0.1) -> np.ndarray:
        """The dummy's poses (x, y, yaw rows) every ``period`` from ``since`` (or the drive's
        start) to its end: what the base sweeps over on the rest of its drive."""
        times = np.append(np.arange(max(since, self.start_time), self.end_time, period),
                          self.end_time)
        return np.array([self.dummy(float(t))[0] for t in times])

    def dummy(self, t: float) -> Tuple[Tuple[float, float, float], np.ndarray, float]:
        """The dummy's pose, world velocity (vx, vy) and yaw rate at time ``t``."""
        s, speed = self.profile.at(t - self.start_time)
        pose = self.path.pose(s)
        velocity = self.path.tangent(s) * speed
        if self._turn is not None:
            turned, rate = self._turn.at(t - self.start_time)
            sign = 1.0 if self._sweep >= 0.0 else -1.0
            return ((pose[0], pose[1], wrap_angle(self._yaw0 + sign * turned)), velocity,
                    sign * rate)
        ds = 1e-3
        yaw_rate = 0.0
        if speed > 0.0:
            ahead = self.path.pose(min(self.path.length, s + ds))
            yaw_rate = wrap_angle(ahead[2] - pose[2]) / ds * speed
        return pose, velocity, yaw_rate

    def update(self, t: float, pose: Vector, velocity: Vector = (0.0, 0.0),
               yaw_rate: float = 0.0, lead: float = 0.0) -> FollowStatus:
        """Command for the robot at ``pose`` (x, y, yaw) moving at world ``velocity`` (vx, vy)
        and ``yaw_rate``, measured at ``t``.

        ``lead`` [s]: how long after ``t`` the command takes effect (the measurement's trip to
        here and the command's to the base). The pose is then predicted that far ahead at the
        measured velocities and compared with the dummy there. A body-frame command computed
        for the heading at ``t`` and applied later, while the base turns, points the wrong way
        by the turn in between: at 1.2 rad/s and 0.2 s, 14 degrees, enough to carry the base
        sideways off its path (into the pool's wall, in a real-time run on a loaded machine)."""
        g = self.gains
        x, y, yaw = (float(v) for v in pose)
        (xd, yd, yawd), vd, wd = self.dummy(t)
        # Where it is, measured: what finished and the errors reported judge.
        distance = math.hypot(xd - x, yd - y)
        yaw_off = abs(wrap_angle(yawd - yaw))
        finished = (t >= self.end_time and distance <= self.position_tolerance
                    and yaw_off <= self.yaw_tolerance)
        if lead > 0.0:
            x, y = x + float(velocity[0]) * lead, y + float(velocity[1]) * lead
            yaw = yaw + float(yaw_rate) * lead
            (xd, yd, yawd), vd, wd = self.dummy(t + lead)
        error = np.array([xd - x, yd - y])
        yaw_error = wrap_angle(yawd - yaw)
        v_world = vd + g.kp_xy * error + g.kd_xy * (vd - np.asarray(velocity, float))
        wz = wd + g.kp_yaw * yaw_error + g.kd_yaw * (wd - yaw_rate)
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy = c * v_world[0] + s * v_world[1], -s * v_world[0] + c * v_world[1]
        # Saturate the translation as a whole, so that the direction is kept.
        scale = max(abs(vx), abs(vy)) / g.max_speed
        if scale > 1.0:
            vx, vy = vx / scale, vy / scale
        wz = max(-g.max_turn, min(g.max_turn, wz))
        if finished:
            vx = vy = wz = 0.0
        return FollowStatus((float(vx), float(vy), float(wz)), (xd, yd, yawd), distance,
                            yaw_off, finished)


def simulate_kinematic(follower: PathFollower, start: Vector, dt: float = 0.02,
                       lag: float = 0.05, duration: Optional[float] = None,
                       disturbance: Tuple[float, float] = (0.0, 0.0), delay: float = 0.0,
                       lead: float = 0.0) -> Tuple[np.ndarray, List[FollowStatus]]:
    """A pure-kinematic holonomic base (first-order velocity lag ``lag`` [s], a constant world
    velocity ``disturbance``) driven by ``follower``; returns the visited poses and statuses.
    ``delay`` [s]: each command takes effect that long after the pose it was computed from
    (the measurement's and the command's trips, as over DDS), until then the last one holds;
    ``lead``: the follower's prediction (``update``'s ``lead``)."""
    pose = np.asarray(start, float).copy()
    body = np.zeros(3)
    t = follower.start_time
    end = follower.end_time + (duration if duration is not None else 5.0)
    poses, statuses = [pose.copy()], []
    pending: Deque[Tuple[float, np.ndarray]] = deque()    # (when it takes effect, command)
    command = np.zeros(3)
    while t < end:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = np.array([c * body[0] - s * body[1], s * body[0] + c * body[1]])
        status = follower.update(t, pose, world, body[2], lead=lead)
        statuses.append(status)
        if status.finished:
            break
        pending.append((t + delay - 1e-9, np.array(status.command)))
        while pending and pending[0][0] <= t:
            command = pending.popleft()[1]
        body += (command - body) * min(1.0, dt / lag)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose[0] += (c * body[0] - s * body[1] + disturbance[0]) * dt
        pose[1] += (s * body[0] + c * body[1] + disturbance[1]) * dt
        pose[2] = wrap_angle(pose[2] + body[2] * dt)
        t += dt
        poses.append(pose.copy())
    return np.array(poses), statuses


class DriveLead:
    """How far ahead of an odometry message a follower's command takes effect, for
    ``update``'s ``lead``: ``trip``, the loop's usual delay (the message's trip to the
    follower, the command's back, and the base taking it at its next step), plus what this
    message is older than the receiver's clock says. At most ``max_lead``: beyond it, a
    prediction at constant velocity is worth less than the measurement.

    The receiver's clock cannot see all of the delay: a receiver that falls behind takes the
    clock's messages as late as the odometry's. Offline (``simulate_kinematic``, the turn
    between the youBot's stands), a fixed 0.1 s keeps the base within 5 cm of its path and
    its outline off the pool's wall for any loop delay up to 0.2 s (4 mm at 0.2 s); without a
    lead, 0.2 s puts its wheels 31 mm into the wall."""

    def __init__(self, trip: float = 0.1, max_lead: float = 0.3) -> None:
        self.trip, self.max_lead = trip, max_lead
        self._ages: List[float] = []

    def lead(self, age: float) -> float:
        age = max(0.0, float(age)) if math.isfinite(age) else 0.0
        self._ages.append(age)
        return min(self.max_lead, self.trip + age)

    def summary(self) -> Dict[str, float]:
        """The messages' ages on arrival by the receiver's clock [s]."""
        if not self._ages:
            return {'samples': 0}
        a = np.asarray(self._ages)
        return {'samples': len(a), 'median': round(float(np.median(a)), 4),
                'p99': round(float(np.percentile(a, 99)), 4), 'max': round(float(a.max()), 4)}
