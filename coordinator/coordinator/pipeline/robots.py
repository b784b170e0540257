"""The robots' parts, as the coordinator drives them (no ROS). Each is the only writer of its
state, and there is one object per robot:
- ``Arm``: an arm's limits, home, plans and the motion it follows, its arrival, its IK through
  the port (``YoubotArm`` solves a path at one tool tilt). A second arm of a kind is a second
  object.
- ``CupPlace``: where the loader's cup last let go (on the youBot's plate or a destination), and
  the way up from there: the loader's next motion, whatever it is, first holds still while the
  material falls free and rises straight up over the place.
- ``BaseDrive``: the youBot's base on its way, a Bezier path from where it is through the
  cell's way points to a stand or home, followed by a PD path follower (run by the port in real
  time, from the ticks in lock-step), until it is there or out of time.
"""
from __future__ import annotations

import math
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from cell_layout.pick_geometry import over_the_belt
from cell_layout.reach import youbot_holds, youbot_tool_quaternion
from controllers import youbot_arm
from controllers.arrays import Vector
from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.path_follower import PathFollower, PDGains, TurnLimits
from controllers.time_optimal import SAMPLE_PERIOD_S, JointLimits, Waypoint, brake, plan
from coordinator.pipeline.clock import Clock
from coordinator.pipeline.model import (
    DOWN,
    RELEASE_HOLD_S,
    Motion,
    Observation,
    Points,
    Ports,
    Settings,
    known,
)
from coordinator.pipeline.record import EventLog
from trial_record.events import EventKind


class Arm:
    """One arm: ``name`` is its robot's (the ports' and the observation's key)."""

    def __init__(self, name: str, limits: JointLimits, ports: Ports, settings: Settings,
                 clock: Clock, log: EventLog) -> None:
        self.name, self.limits = name, limits
        self.ports, self.s, self.clock, self.log = ports, settings, clock, log
        self._motion: Optional[Motion] = None
        self._home: Optional[np.ndarray] = None

    # --- where it is ----------------------------------------------------------------------------
    def q(self, obs: Observation) -> np.ndarray:
        """Its joint positions as observed."""
        return obs.arms[self.name].q

    def dq(self, obs: Observation) -> Optional[np.ndarray]:
        """Its measured joint velocities, if known."""
        return obs.arms[self.name].dq

    def holding(self, obs: Observation) -> bool:
        """Whether its gripping tool holds something, as last published."""
        return obs.arms[self.name].holding

    def armed(self, obs: Observation) -> bool:
        """Whether its gripping tool is switched on (closed), as last published."""
        return obs.arms[self.name].armed

    @property
    def home(self) -> np.ndarray:
        """Its start (and end) pose: where it stood at the run's first observation."""
        return known(self._home, f'the {self.name}\'s home pose')

    def started(self, obs: Observation) -> None:
        """The run's first observation: the arm's pose now is its home pose."""
        self._home = np.array(self.q(obs), float)

    # --- its motions ----------------------------------------------------------------------------
    def plan(self, q: Vector, waypoints: Sequence[Waypoint], wait: float = 0.0,
             start: Optional[float] = None) -> Points:
        """A time-optimal motion from rest at ``q`` through ``waypoints``, starting ``wait``
        after the plan latency from now (the convention of every plan here), or at ``start``."""
        t0 = self.clock.now + self.s.plan_latency if start is None else start
        motion = plan(q, waypoints, self.limits, t0 + wait)
        # The controller starts from where the arm is: the start sample is sent only as the end
        # of a wait (a hold at the current position).
        points = motion.points()
        if len(points) == 1:            # already there: hold it, a sample period on
            t, q, v, a = points[0]
            return [(t + SAMPLE_PERIOD_S, q, v, a)]
        return points[0 if wait > 0.0 else 1:]

    def send(self, points: Points, start: Optional[float] = None) -> Motion:
        """Send a motion planned now, its first segment starting after the plan latency (the
        convention of every plan here) or at ``start``; the port may schedule it later,
        whole."""
        motion = Motion(self.name, points)
        motion.start = self.clock.now + self.s.plan_latency if start is None else start
        delay = self.ports.trajectory(self.name, motion.points, motion.start)
        if delay:
            motion.delay(delay)
        self._motion = motion
        return motion

    def send_continuing(self, now: float, t1: float, points: Points) -> None:
        """Replace the running motion from its sample at ``t1`` on by ``points`` (which begin
        there, in that sample's state). The message repeats the motion's own samples between
        ``now`` and ``t1`` and is stamped ``now``: the controller, which skips the points
        already past when it takes it, joins it from where the running motion has the arm,
        whenever it arrives. (A new motion starts in the future, from rest: a controller holds
        its position until then, and from there a point of a motion it was following is out of
        reach; nor may the port delay it, which would tear it off that motion.)"""
        kept = [p for p in self.motion.points if now < p[0] < t1 - 1e-9]
        motion = Motion(self.name, kept + list(points), start=now)
        self.ports.trajectory(self.name, motion.points, now, continuing=True)
        self._motion = motion

    def stop(self, t: float) -> bool:
        """Stop the running motion as soon as the joints allow, from its first sample after
        ``t`` (the plan latency ahead: the controller joins it there), at rest where it comes
        to a stop; False if the motion has no sample left after ``t`` (it ends anyway)."""
        after = [p for p in self.motion.points if p[0] > t] if self.has_motion else []
        if not after:
            return False
        t1, q1, v1, a1 = after[0]
        self.send_continuing(self.clock.now, t1, brake(q1, v1, a1, self.limits, t1).points())
        return True

    def hold(self, q: np.ndarray) -> None:
        """Hold still at ``q`` from the plan latency on (replacing a motion not yet begun)."""
        self.send([(self.clock.now + self.s.plan_latency, q, np.zeros_like(q),
                    np.zeros_like(q))])

    def go_home(self, obs: Observation, say: bool = True) -> None:
        """Back to its home pose (``say``: as a ``returning`` event)."""
        self.send(self.plan(self.q(obs), [Waypoint(self.home.copy())]))
        if say:
            self.log.event(obs.now, EventKind.RETURNING, self.name)

    @property
    def has_motion(self) -> bool:
        return self._motion is not None

    @property
    def motion(self) -> Motion:
        """Its current motion (one has been sent)."""
        return known(self._motion, f'a motion of the {self.name}')

    def arrived(self, obs: Observation) -> Optional[bool]:
        """After a motion's end: True when the arm is at its goal and at rest (its measured
        joint velocities, if known), None while it may still get there, False once it is later
        than the settle margin (a stalled arm). At rest matters when the simulator took the
        motion in late: at its planned end the arm is then still moving, near its goal."""
        motion, now, dq = self._motion, obs.now, self.dq(obs)
        if motion is None or now < motion.end:
            return None
        if (float(np.max(np.abs(self.q(obs) - motion.goal))) <= self.s.arrive_tolerance
                and (dq is None or float(np.max(np.abs(dq))) <= self.s.rest_speed)):
            return True
        return False if now > motion.end + self.s.settle_margin else None

    def arrival_time(self, q: np.ndarray) -> float:
        """When its current motion passes closest to ``q`` (as the port scheduled it)."""
        return min(self.motion.points, key=lambda p: float(np.max(np.abs(p[1] - q))))[0]

    # --- its kinematics, through the port -------------------------------------------------------
    def solve(self, position: Vector, orientation: Vector, frame: str,
              seed: Vector) -> Optional[np.ndarray]:
        q, why = self.ports.solve(self.name, position, orientation, frame, seed)
        if q is None:
            self.log.event(self.clock.now, EventKind.IK_FAILED, self.name,
                           detail=f'{np.round(position, 3).tolist()}: {why}')
        return q

    def solve_path(self, positions: Sequence[Vector],
                   seed: Vector) -> Optional[List[np.ndarray]]:
        """Joint positions for the tool pointing down at each of ``positions`` (world), each
        seeded with the one before; None if any has no solution."""
        qs = []
        for p in positions:
            q = self.solve(p, DOWN, 'world', seed)
            if q is None:
                return None
            qs.append(q)
            seed = q
        return qs


class YoubotArm(Arm):
    """The youBot's arm: it reaches the plate's far slots only leaning outwards, so its paths
    are solved at one tool tilt, and it holds a load only in some poses."""

    # The tool tilt [deg] of the last path solve_tilted found.
    tilt_deg = 0

    def solve_tilted(self, points: Sequence[np.ndarray], seed: np.ndarray,
                     payload: float = 0.0, held_from: int = 0,
                     tilts: Sequence[int] = tuple(range(0, 90, 10))
                     ) -> Optional[List[np.ndarray]]:
        """Joint positions for a path whose every point has the same tool tilt: a material
        held at one tilt stays level only if it is set down at the same tilt. From point
        ``held_from`` on the arm holds ``payload`` kg: a tilt whose poses there its joints
        cannot hold at rest (youbot_holds) is not taken. The first of ``tilts`` [deg] that
        works is taken (and kept in ``tilt_deg``)."""
        heavy = False
        for tilt_deg in tilts:
            plan: List[np.ndarray] = []
            q = seed
            for p in points:
                solution, _ = self.ports.solve(self.name, p, youbot_tool_quaternion(
                    p, math.radians(tilt_deg)), 'base_link', q)
                if solution is None:
                    break
                q = solution
                plan.append(q)
            if len(plan) == len(points):
                if youbot_holds(plan[held_from:], payload):
                    self.tilt_deg = tilt_deg
                    return plan
                heavy = True
        why = (f'not held at rest with {payload} kg' if heavy else 'at any one tilt up to 80 deg')
        self.log.event(self.clock.now, EventKind.IK_FAILED, self.name,
                       detail=f'{np.round(points[1 if len(points) > 1 else 0], 3).tolist()} via '
                              f'{np.round(points[-1], 3).tolist()} {why}')
        return None


def youbot_limits(settings: Settings) -> JointLimits:
    """The youBot arm's joint limits, the velocity scaled by its setting."""
    return JointLimits(np.full(5, youbot_arm.JOINT_VELOCITY_LIMIT),
                       np.full(5, youbot_arm.JOINT_ACCELERATION_LIMIT),
                       np.full(5, youbot_arm.JOINT_JERK_LIMIT)).scaled(settings.youbot_scaling)


class CupPlace:
    def __init__(self, arm: Arm, layout: CellLayout, settings: Settings) -> None:
        self.arm, self.layout, self.s = arm, layout, settings
        self.then: Optional[np.ndarray] = None      # where the cup rises to from its place
        self.above: Optional[np.ndarray] = None     # above the place (x, y, z), joints
        self.above_q: Optional[np.ndarray] = None
        self.onto_plate = False                     # the last place was on the youBot's plate
        self.clear_point: Optional[np.ndarray] = None   # clear of the place once here (joints)
        # The cup has just let go on the plate or the ground target: the next motion rises
        # first (straight up, after the release hold), whatever it is.
        self.at_release = False
        self.clear_at = -math.inf                   # when the cup is clear of the place

    def adopt(self, then: np.ndarray, above: np.ndarray, above_q: np.ndarray,
              onto_plate: bool) -> None:
        """The place the arm is on its way to: where the cup rises from it to."""
        self.then, self.above, self.above_q, self.onto_plate = then, above, above_q, onto_plate

    def released(self) -> None:
        """The cup has just let go there."""
        self.at_release = True

    def clear(self, now: float) -> bool:
        """Whether the cup is away from where it last let go (not about to rise from it)."""
        return not self.at_release and now >= self.clear_at

    def plan(self, obs: Observation, waypoints: List[Waypoint],
             start: Optional[float] = None, edge: Optional[np.ndarray] = None) -> Points:
        """From a release: the hold, then straight up to above the place and over the belt's
        edge at ``edge`` (joints; towards a pick), or without it up to the carry height."""
        waypoints, wait = self.from_release(waypoints, edge)
        if self.at_release:
            # Clear of the place once straight above it: the cup may be switched on there
            # (what it let go is place_height below it), and the youBot may leave.
            self.clear_point = self.above_q
        return self.arm.plan(self.arm.q(obs), waypoints, wait, start)

    def from_release(self, waypoints: List[Waypoint], edge: Optional[np.ndarray] = None
                     ) -> Tuple[List[Waypoint], float]:
        """``waypoints``, after the rise from a place the cup has just let go at (see plan),
        and how long the motion waits first."""
        if not self.at_release:
            return list(waypoints), 0.0
        rise = self.s.timing.place_descend
        if edge is not None:
            above = known(self.above_q, 'the point above the place')
            # (Up over the place first where the swing from there to the edge would bulge out
            # over the belt, low: see PickPlanner.place_way.)
            then = known(self.then, 'the rise from the place')
            over = ([Waypoint(then, stop=False)] if over_the_belt(self.layout, above, edge, 0.0)
                     and float(np.max(np.abs(then - above))) > 1e-6 else [])
            first = [Waypoint(above, stop=False, min_time=rise), *over,
                     Waypoint(edge, stop=False)]
        else:
            # Straight up over the place first (over what else is there: a swing from the
            # release towards home swept two materials off their slots beside it), then on.
            above = known(self.above_q, 'the point above the place')
            then = known(self.then, 'the rise from the place')
            first = [Waypoint(above, stop=False, min_time=rise)]
            if float(np.max(np.abs(then - above))) > 1e-6:
                first.append(Waypoint(then, stop=not waypoints))
            elif not waypoints:
                first = [Waypoint(above, min_time=rise)]
        return first + list(waypoints), RELEASE_HOLD_S

    def after_send(self) -> None:
        """A motion was sent: one from a release has left it (clear of it when it passes the
        clear point)."""
        if self.at_release:
            self.at_release = False
            self.clear_at = self.arm.arrival_time(known(self.clear_point, 'the clear point'))


class BaseDrive:
    def __init__(self, robot: str, ports: Ports, log: EventLog, settings: Settings) -> None:
        self.robot, self.ports, self.log, self.s = robot, ports, log, settings
        self._follower: Optional[PathFollower] = None   # while the base drives
        self._followed = False                           # the port runs the follower
        self.goal = ''                                   # the last drive's: a stand, or home
        self.target: Optional[Pose2D] = None             # the drive's end pose
        self.deadline = math.inf

    @property
    def driving(self) -> bool:
        """Whether the base is on its way."""
        return self._follower is not None

    @property
    def follower(self) -> Optional[PathFollower]:
        """The drive's follower, while the base is on its way."""
        return self._follower

    def steer(self, obs: Observation) -> None:
        """The base along its path, with its follower, until it is there or out of time."""
        follower = known(self._follower, 'the path follower')
        base = obs.bases[self.robot]
        status = follower.update(obs.now, base.pose, base.velocity[:2], base.velocity[2])
        if not self._followed:
            self.ports.drive(self.robot, *status.command)
        if not (status.finished or obs.now > self.deadline):
            return
        self._follower = None
        self.ports.follow(self.robot, None)
        self.ports.drive(self.robot, 0.0, 0.0, 0.0)
        if not status.finished:
            self.log.event(obs.now, EventKind.DRIVE_STALLED, self.robot, detail=(
                f'{status.position_error * 1000:.0f} mm from {self.goal}'))
        self.log.event(obs.now, EventKind.ARRIVED, self.robot, detail=(
            f'{self.goal}; {base.located}' if base.located else self.goal))

    def follow(self, obs: Observation, target: Pose2D, via: Sequence[Any], goal: str,
               clear: Callable[[PathFollower], bool] = lambda follower: True) -> bool:
        """The base off along a path from where it is through ``via`` to ``target`` (at stand
        or home ``goal``), if the drive is ``clear`` (the fleet's rule); whether it set off."""
        follower = self.path_to(obs, target, via)
        path = follower.path
        if not clear(follower):
            return False
        self._follower = follower
        self._followed = self.ports.follow(self.robot, follower)
        self.goal, self.target = goal, target
        self.log.event(obs.now, EventKind.DRIVING, self.robot,
                       detail=f'to {goal}, {path.length:.2f} m')
        self.deadline = (obs.now + follower.profile.duration + self.s.drive_margin)
        return True

    def path_to(self, obs: Observation, target: Pose2D, via: Sequence[Any]) -> PathFollower:
        """The follower of a drive from where the base is through ``via`` to ``target``."""
        x, y, yaw = (float(v) for v in obs.bases[self.robot].pose)
        path = BezierPath(key_poses_between((x, y, yaw), target, via))
        # Mecanum: the heading turns on its own profile in time while the base travels the
        # path, both over the same time (a short path with a large turn takes the turn's).
        return PathFollower(
            path, obs.now, self.s.drive_speed, self.s.drive_accel,
            PDGains(max_speed=self.s.base_max_speed, max_turn=self.s.base_max_turn),
            turn=TurnLimits(self.s.drive_turn, self.s.drive_turn_accel))

    def stand_pose(self, obs: Observation) -> Pose2D:
        """Where the base stands for its unloads: its drive's end while it is on its way."""
        if self.driving:
            return known(self.target, 'the drive\'s end')
        return obs.bases[self.robot].pose
