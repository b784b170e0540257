"""One place that advances the physics: applies guarded commands, steps, schedules outputs."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Protocol, Sequence, Tuple

import numpy as np

from controllers.cmd_guard import CommandGuard, GuardResult, non_finite_fields, rate_limited
from controllers.joint_trajectory import TrajectoryRequest, TrajectoryResult, slowed
from controllers.lockstep import next_on_grid
from sim_bridge.base_clearance import BaseClearance, Closest
from sim_bridge.joint_speed import Braked
from sim_bridge.world import SimWorld

Twist3 = Tuple[float, float, float]
"""A base's body twist, (vx, vy, wz) [m/s, m/s, rad/s]: every drive's one shape (a differential
drive's vy is 0)."""

ZERO: Twist3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TwistVerdict:
    """What the runner made of a body twist sent to a base.

    ``accepted``: the base follows ``command`` from the next step on (clamped to its limits);
    if not, it stops. ``notes``: (kind, text) for each thing the sender should hear: kinds
    'non-finite', 'old stamp', 'future stamp', 'fault', 'sideways', 'clamped'."""
    accepted: bool
    command: Twist3
    notes: Tuple[Tuple[str, str], ...] = ()


class StepSink(Protocol):
    """Receives what a step produces; the ROS node implements it by publishing."""

    def on_clock(self, time_ns: int) -> None: ...

    def on_state(self, robot: str, time_ns: int) -> None: ...

    def on_camera_due(self, index: int, time_ns: int,
                      render: Callable[[], np.ndarray]) -> None:
        """A camera frame is due; call ``render()`` only if someone wants the image."""

    def on_command_timeout(self, robot: str) -> None: ...

    def on_command_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        """The command a driven robot's wheels follow changed at ``time_ns`` to ``command``."""

    def on_world_state(self, time_ns: int) -> None:
        """The world's props (materials) are due; called only for worlds that have them."""

    def on_belt(self, time_ns: int) -> None:
        """The conveyor's drive reports, if the world has one (on its encoder's own grid)."""

    def on_scan(self, robot: str, time_ns: int) -> None:
        """A robot's laser scanner has a scan due (on its own grid)."""

    def on_trajectory_aborted(self, robot: str, controller: str, reason: str) -> None:
        """A joint group stopped following its trajectory and holds where it is."""

    def on_fault(self, robot: str, reason: str) -> None:
        """A robot's physics state went non-finite: it was put back at its start pose, at
        rest, and takes no commands until the runner is reset."""

    def on_body_lost(self, name: str, what: str) -> None:
        """A material or a spawned body left the world (its state not finite, too fast, too
        far: free_bodies.py) and was taken out of it, or a static body it poisoned was put
        back: ``what`` says which, and why."""

    def on_joints_braked(self, robot: str, time_ns: int, braked: Sequence[Braked]) -> None:
        """Joints of a robot were faster than their limits after the step at ``time_ns`` and
        were braked back to them (joint_speed.py): each with the speed it had and the brake
        torque it took."""

    def on_bases_closest(self, closest: Closest) -> None:
        """The mobile bases came nearer each other than told so far (base_clearance.py)."""


class NullSink:
    """A StepSink that wants nothing: subclass it and override what you need."""

    def on_clock(self, time_ns: int) -> None:
        pass

    def on_state(self, robot: str, time_ns: int) -> None:
        pass

    def on_camera_due(self, index: int, time_ns: int,
                      render: Callable[[], np.ndarray]) -> None:
        pass

    def on_command_timeout(self, robot: str) -> None:
        pass

    def on_command_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        pass

    def on_world_state(self, time_ns: int) -> None:
        pass

    def on_belt(self, time_ns: int) -> None:
        pass

    def on_scan(self, robot: str, time_ns: int) -> None:
        pass

    def on_trajectory_aborted(self, robot: str, controller: str, reason: str) -> None:
        pass

    def on_fault(self, robot: str, reason: str) -> None:
        pass

    def on_body_lost(self, name: str, what: str) -> None:
        pass

    def on_joints_braked(self, robot: str, time_ns: int, braked: Sequence[Braked]) -> None:
        pass

    def on_bases_closest(self, closest: Closest) -> None:
        pass


@dataclass(frozen=True)
class DriveLimits:
    """Fallbacks for the bases whose world entry sets none of these; an acceleration of None
    means no limit."""

    max_speed: float = 0.2
    max_turn: float = 0.2
    cmd_vel_timeout: float = 0.5
    max_accel: Optional[float] = None          # [m/s^2], each of linear.x and linear.y
    max_turn_accel: Optional[float] = None     # [rad/s^2]


class SimRunner:
    """Advances a SimWorld step by step.

    Each step: the command of every driven robot is taken from its guard (which zeroes it once
    it is older than the timeout, in simulated time) and, for a robot with acceleration limits,
    approached at no more than those; physics advances one fixed step, then /clock is due at
    ``clock_rate`` (or every step), robot states at ``state_rate`` and each camera at its own rate
    (each on its own grid of simulated time); the sink renders a camera only if someone wants
    the image.
    """

    def __init__(self, world: SimWorld, limits: DriveLimits, state_rate: float,
                 world_state_rate: float = 10.0, clock_rate: float = 0.0) -> None:
        """``clock_rate``: /clock is due on its own grid at this rate [Hz of simulated time];
        0: after every physics step."""
        if not (state_rate > 0.0 and math.isfinite(state_rate)):
            raise ValueError(f'state_rate must be > 0, got {state_rate}')
        if not (clock_rate >= 0.0 and math.isfinite(clock_rate)):
            raise ValueError(f'clock_rate must be >= 0, got {clock_rate}')
        self.world = world
        self.clearance = BaseClearance(world.robots)        # (the bases' closest approach)
        dt_ns = round(world.time_step * 1e9)
        self.clock_period_ns = max(dt_ns, round(1e9 / clock_rate)) if clock_rate else dt_ns
        self._clock_next_ns = 0
        self.last_clock_ns = -1           # the last /clock the sink was given [ns]
        # States go out at the first step at or after each point of their own time grid, so the
        # average rate is exact even when the period is not a whole number of steps.
        self.state_period_ns = max(dt_ns, round(1e9 / state_rate))
        self._state_next_ns = 0
        self.world_state_period_ns = max(dt_ns, round(1e9 / world_state_rate))
        self._world_state_next_ns = 0
        self.guards: Dict[str, CommandGuard] = {}
        self._max_change: Dict[str, Tuple[float, ...]] = {}   # per step, with accel limits
        for name, robot in world.robots.items():
            if robot.drive is None:
                continue
            own = robot.config.limits
            speed = own.max_speed if own.max_speed is not None else limits.max_speed
            turn = own.max_turn if own.max_turn is not None else limits.max_turn
            # (vx, vy, wz) for every drive; a differential drive's vy is held at 0.
            sideways = speed if 'linear.y' in robot.drive.components else 0.0
            self.guards[name] = CommandGuard((speed, sideways, turn), limits.cmd_vel_timeout,
                                             robot.drive.wheel_speeds, robot.drive.wheel_limit)
            accel = own.max_accel if own.max_accel is not None else limits.max_accel
            turn_accel = (own.max_turn_accel if own.max_turn_accel is not None
                          else limits.max_turn_accel)
            if accel is not None or turn_accel is not None:
                accel = math.inf if accel is None else accel
                turn_accel = math.inf if turn_accel is None else turn_accel
                self._max_change[name] = tuple(a * world.time_step
                                               for a in (accel, accel, turn_accel))
        self._applied: Dict[str, Twist3] = {name: ZERO for name in self.guards}
        self._timed_out: Dict[str, bool] = {name: False for name in self.guards}
        # Robots put back after a non-finite physics state, and why: no commands until reset.
        self.faults: Dict[str, str] = {}
        self._arms = [robot for robot in world.robots.values() if robot.controllers]
        self._camera_period_ns: List[int] = [
            max(dt_ns, round(1e9 / cam.config.rate)) for cam in world.cameras]
        self._camera_next_ns: List[int] = [0 for _ in world.cameras]
        # The conveyor drive's encoder, on its own grid (0: none).
        encoder = world.conveyor.config.encoder if world.conveyor is not None else None
        self._encoder_period_ns = (max(dt_ns, round(1e9 / encoder.rate))
                                   if encoder is not None else 0)
        self._encoder_next_ns = 0
        # Each laser scanner, on its own grid: robot: [period, next due] [ns].
        self._laser_due = {name: [max(dt_ns, round(1e9 / robot.config.laser.rate)), 0]
                           for name, robot in world.robots.items()
                           if robot.config.laser is not None}

    def applied(self, robot: str) -> Twist3:
        """The command a driven robot's wheels follow now."""
        return self._applied[robot]

    def holonomic(self, robot: str) -> bool:
        return self.guards[robot].limits[1] > 0.0

    def judge_twist(self, robot: str, values: Sequence[float],
                    stamp: Optional[float] = None) -> TwistVerdict:
        """Take a body twist sent to a driven robot, or stop it: ``values`` are the six numbers
        of a geometry_msgs/Twist (linear x, y, z, angular x, y, z), ``stamp`` when it was sent
        [s of simulated time] (None: now).

        A non-finite number in any field means a broken sender, and a stamp further from now
        than the command timeout (either way) a command not meant for now: both stop the
        robot, as diff_drive_controller judges a stamp. A differential drive ignores a
        sideways speed; every drive is clamped to its limits (``command``)."""
        broken = non_finite_fields(values)
        if broken:
            self.reject(robot)
            return TwistVerdict(False, ZERO, (('non-finite', f'rejected: non-finite {broken}; '
                                                              'stopping'),))
        now, timeout = self.world.sim_time, self.guards[robot].timeout
        if stamp is not None and abs(now - stamp) > timeout:
            self.reject(robot)
            return TwistVerdict(False, ZERO, (
                ('old stamp' if stamp < now else 'future stamp',
                 f"rejected: stamped {stamp:.3f} s, the simulator's clock reads {now:.3f} s "
                 f'(beyond cmd_vel_timeout {timeout:g} s; is the sender on simulated time?); '
                 'stopping'),))
        vx, vy, wz = float(values[0]), float(values[1]), float(values[5])
        notes: List[Tuple[str, str]] = []
        if vy != 0.0 and not self.holonomic(robot):
            notes.append(('sideways', f'linear.y {vy:.3f} ignored: a differential drive '
                                      'cannot move sideways'))
            vy = 0.0
        result = self.command(robot, vx, vy, wz)
        if not result.accepted:
            notes.append(('fault', f'rejected: {result.reason}'))
        elif result.clamped:
            wheels = (f', wheels {self.world.robots[robot].drive_wheel_limit():g} rad/s'
                      if result.wheel_limited else '')
            notes.append(('clamped', f'{self.shown(robot, (vx, vy, wz))} clamped to '
                                     f'{self.shown(robot, result.command)} (limits '
                                     f'{self.shown(robot, self.guards[robot].limits)}{wheels})'))
        return TwistVerdict(result.accepted, _twist(result.command), tuple(notes))

    def shown(self, robot: str, twist: Sequence[float]) -> str:
        """A twist as a robot takes it: (vx, wz) for a differential drive, (vx, vy, wz) for
        one that moves sideways."""
        used = twist if self.holonomic(robot) else (twist[0], twist[2])
        return '(' + ', '.join(f'{v:.3f}' for v in used) + ')'

    def command(self, robot: str, vx: float, vy: float, wz: float) -> GuardResult:
        """Take a body twist for a driven robot (or stop on bad input), applied from the next
        step on (``on_command_applied`` reports when the wheels' command changes). The result's
        command is (vx, vy, wz), clamped; a differential drive's vy is held at 0."""
        if robot in self.faults:
            self.guards[robot].stop()
            return GuardResult(False, ZERO,
                               reason=f'{self.faults[robot]}; reset the simulator to go on')
        result = self.guards[robot].submit((vx, vy, wz), self.world.sim_time)
        self._timed_out[robot] = False
        return result

    def reject(self, robot: str) -> None:
        """A broken command: the robot stops from the next step on, as if it had timed out."""
        self.guards[robot].stop()
        self._timed_out[robot] = False

    def set_trajectory(self, robot: str, controller: str, request: TrajectoryRequest,
                       path_tolerance: Optional[Sequence[float]] = None) -> TrajectoryResult:
        """Validate a trajectory for a joint group and, if valid, follow it from now, aborting
        it if a joint lags its reference by more than its path tolerance (per joint, 0: not
        checked; None: the controller's own, from the world file)."""
        if robot in self.faults:
            return TrajectoryResult(False, f'{self.faults[robot]}; reset the simulator to go on')
        group = self.world.robots[robot].controllers[controller]
        scale = self.world.config.perturbations.robots.velocity_scale
        if scale != 1.0:
            request = slowed(request, scale)     # a slower arm (a perturbation)
        result = group.follower.set_trajectory(request, self.world.sim_time)
        if result.accepted:
            group.active_path_tolerance = (group.path_tolerance if path_tolerance is None else
                                           np.asarray(path_tolerance, float))
        return result

    def check_robot(self, name: str, sink: 'StepSink') -> bool:
        """Check a robot's physics state and its joint groups' references against their
        feedback; False if the robot had to be put back (a fault). Called at the state rate."""
        robot = self.world.robots[name]
        problem = robot.state_problem()
        if problem:
            repaired = self._fault(name)
            self.faults[name] = f'{name}: {problem}' + (
                f' (and the pose of {", ".join(repaired)}, put back)' if repaired else '')
            sink.on_fault(name, self.faults[name])
            return False
        for controller, group in robot.controllers.items():
            if group.fault:
                why, group.fault = group.fault, ''
                sink.on_trajectory_aborted(name, controller, why)
                continue
            if not group.follower.active or group.follower.finished(self.world.sim_time):
                continue
            tolerance = group.active_path_tolerance
            if not np.any(tolerance > 0.0):
                continue
            error = np.abs(group.desired.positions - group.actual()[0])
            broken = (tolerance > 0.0) & ~(error <= tolerance)
            if np.any(broken):
                j = int(np.argmax(broken))
                group.hold_current()
                contacts = self.world.contacts_of(group)
                sink.on_trajectory_aborted(name, controller, (
                    f'path tolerance violated: {group.joint_names[j]} is {error[j]:.4f} from its '
                    f'reference (tolerance {tolerance[j]:.4f})'
                    + (f'; in contact: {", ".join(contacts)}' if contacts else '')))
        return True

    def _fault(self, name: str) -> List[str]:
        """Load a robot again, stopped; the static bodies it poisoned are put back."""
        robot = self.world.robots[name]
        suction = self.world.suctions.get(name)
        if suction is not None:
            suction.reset()
        robot.reload()
        repaired = self.world.repair_static()
        if name in self.guards:
            self.guards[name].stop()
            self._applied[name] = ZERO
        return repaired

    def advance(self, steps: int, sink: StepSink) -> None:
        world = self.world
        for _ in range(steps):
            now = world.sim_time
            # Position targets for the end of this step.
            for robot in self._arms:
                robot.apply_controllers(now + world.time_step)
            for name, guard in self.guards.items():
                command = guard.active_command(now)
                if name in self._max_change:
                    command = rate_limited(self._applied[name], command,
                                           self._max_change[name])
                if guard.timed_out(now) and not self._timed_out[name]:
                    self._timed_out[name] = True
                    sink.on_command_timeout(name)
                if command != self._applied[name]:
                    self._apply(name, _twist(command))
                    sink.on_command_applied(name, world.sim_time_ns, self._applied[name])
            world.step()
            self._check_bases(sink)
            t_ns = world.sim_time_ns
            for name, _, braked in world.take_braked():
                sink.on_joints_braked(name, t_ns, braked)
            closest = self.clearance.update(t_ns * 1e-9)
            if closest is not None:
                sink.on_bases_closest(closest)
            self._outputs_due(t_ns, sink)

    def _outputs_due(self, t_ns: int, sink: StepSink) -> None:
        """After a step at ``t_ns``: the periodic outputs that fall due, each on its grid."""
        world = self.world
        if t_ns >= self._clock_next_ns:
            self._clock_next_ns = next_on_grid(t_ns, self.clock_period_ns)
            self.tick_clock(sink)
        if t_ns >= self._state_next_ns:
            self._state_next_ns = next_on_grid(t_ns, self.state_period_ns)
            world.check_free_bodies(pose=True)
            self._report_lost(sink)
            for name in world.robots:
                self.check_robot(name, sink)
                sink.on_state(name, t_ns)
        if self._encoder_period_ns and t_ns >= self._encoder_next_ns:
            self._encoder_next_ns = next_on_grid(t_ns, self._encoder_period_ns)
            sink.on_belt(t_ns)
        for name, due in self._laser_due.items():
            if t_ns >= due[1]:
                due[1] = next_on_grid(t_ns, due[0])
                sink.on_scan(name, t_ns)
        if world.source is not None and t_ns >= self._world_state_next_ns:
            self._world_state_next_ns = next_on_grid(t_ns, self.world_state_period_ns)
            sink.on_world_state(t_ns)
        for i, cam in enumerate(world.cameras):
            if t_ns >= self._camera_next_ns[i]:
                # Keep the camera's own grid of due times, skipping frames nobody wanted.
                self._camera_next_ns[i] = next_on_grid(t_ns, self._camera_period_ns[i])
                sink.on_camera_due(i, t_ns, functools.partial(world.render, cam))

    def _check_bases(self, sink: StepSink) -> None:
        """After every step: no body is stepped on with a state that is not finite. The free
        bodies' velocities were checked by the world's step; the robots' bases are here (their
        joints, at the state rate: check_robot)."""
        for name, robot in self.world.robots.items():
            if robot.state_problem(joints=False):
                self.check_robot(name, sink)
        self._report_lost(sink)

    def _report_lost(self, sink: StepSink) -> None:
        for lost in self.world.take_lost():
            sink.on_body_lost(lost.name, lost.what)

    def tick_clock(self, sink: StepSink) -> None:
        """/clock now, unless it already shows this time."""
        t_ns = self.world.sim_time_ns
        if t_ns != self.last_clock_ns:
            self.last_clock_ns = t_ns
            sink.on_clock(t_ns)

    def reset(self) -> None:
        """Every robot back at its start pose, at rest (a body whose state is not finite is
        loaded again), faults cleared."""
        for robot in self.world.robots.values():
            if robot.state_problem():
                robot.reload()
        self.world.repair_static()
        self.world.reset()
        self.faults.clear()
        self.clearance.reset()
        for name, guard in self.guards.items():
            guard.stop()
            self._applied[name] = ZERO
            self._timed_out[name] = False

    def stop_all(self) -> None:
        for name, guard in self.guards.items():
            guard.stop()
            self._apply(name, ZERO)

    def _apply(self, robot: str, command: Twist3) -> None:
        self.world.robots[robot].set_body_twist(*command)
        self._applied[robot] = command


def _twist(values: Sequence[float]) -> Twist3:
    vx, vy, wz = values
    return (float(vx), float(vy), float(wz))
