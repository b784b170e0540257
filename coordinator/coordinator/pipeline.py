"""The pipeline run as an explicit state machine (no ROS): sorting, delivery and transport.

Two machines share one clock. The loader (the Zu 12) watches the vision's detections, stops the
belt when the front material reaches the pick point, picks it with the suction cup, puts purple
on the ground target and the rest on the youBot's plate. The transport (the youBot) waits for its
load, drives along Bezier paths with a PD follower, unloads with its arm (orange into the pool,
blue onto the platform) and drives home. Both arms end at their start poses.

The machine acts through ``Ports`` (IK, trajectories, suction, belt, base twist, events) and
sees the world through ``Observation``; the node implements both over ROS, tests fake them.
Every state has a deadline; a missed grasp is retried, then reported; a material that goes off
the belt end is reported; a port that stops answering (``NodeTimeout``) ends the run. The run
always ends with a ``RunResult``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Protocol, Sequence, Tuple

import numpy as np

from controllers.arm_kinematics import motion_duration
from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.path_follower import PathFollower
from controllers.pick_place import PickTiming, pick_waypoints, place_waypoints
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M
from coordinator.layout import (PLATE_SLOTS_IN_BASE_M, PLATE_TOP_IN_BASE_M, CellLayout,
                                slot_in_world, world_to_base)

DOWN = (1.0, 0.0, 0.0, 0.0)                  # tool z pointing down (x, y, z, w)
# A material seen this recently before the belt stopped is in the camera's view [s]; its pick
# waits this long after the stop, for frames of it at rest [s].
VIEW_GAP_S = 0.2
STOP_FRAME_WAIT_S = 0.4
Points = List[Tuple[float, np.ndarray]]      # (absolute time [s], joint positions)


class NodeTimeout(RuntimeError):
    """A node the coordinator depends on did not answer in time."""


@dataclass(frozen=True)
class Detection:
    id: int
    color: str
    position: np.ndarray          # world [m], the material's centre, at ``stamp``
    stamp: float                  # the camera frame's time [s]
    hits: int


@dataclass
class Observation:
    now: float
    zu12_q: np.ndarray
    youbot_q: np.ndarray
    youbot_pose: Pose2D
    youbot_velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)   # world vx, vy, wz
    zu12_holding: bool = False
    youbot_holding: bool = False
    detections: Sequence[Detection] = ()


@dataclass(frozen=True)
class Event:
    time: float
    kind: str                     # seen, stopped_belt, picked, placed, delivered, ...
    robot: str = ''
    material: int = -1
    color: str = ''
    detail: str = ''


class Ports(Protocol):
    def solve(self, arm: str, position: Sequence[float], orientation: Sequence[float],
              frame: str, seed: Sequence[float]) -> Tuple[Optional[np.ndarray], str]:
        """Joint positions for the tool at a pose, or (None, why). Raises NodeTimeout."""

    def trajectory(self, arm: str, points: Points) -> None: ...

    def grip(self, arm: str, on: bool) -> Tuple[bool, str]:
        """Arm (on) or release (off) the arm's gripping tool. Raises NodeTimeout."""

    def belt(self, speed: float) -> Optional[float]:
        """Set the belt speed; returns the (simulated) time it took effect if that is later
        than the decision (real time), or None (lock-step: at once). Raises NodeTimeout."""

    def drive(self, vx: float, vy: float, wz: float) -> None: ...

    def event(self, event: Event) -> None: ...


@dataclass(frozen=True)
class Settings:
    pick_x: float = 0.0               # the belt stops when the front material reaches this x
    confirm_hits: int = 8             # frames a track needs before it is acted on
    max_retries: int = 1              # extra grasp attempts on a missed grasp
    zu12_scaling: float = 1.0         # fraction of the Zu 12's joint speed limits
    youbot_scaling: float = 1.0
    arrive_tolerance: float = 0.03    # joint error [rad] that counts as arrived
    settle_margin: float = 2.0        # a motion may end this late before it is a failure [s]
    drive_margin: float = 15.0        # a drive may end this late [s]
    idle_timeout: float = 20.0        # belt running, nothing new to pick: loading is over [s]
    run_timeout: float = 300.0        # the whole run [s]
    drive_speed: float = 0.4          # the dummy's speed along a path [m/s]
    # A motion starts this much later than planned-for "now" (real time: the plan's IK calls
    # and the message's trip; a late first segment would be too fast and rejected) [s].
    plan_latency: float = 0.0
    drive_accel: float = 0.4
    timing: PickTiming = PickTiming()


@dataclass
class Material:
    id: int
    color: str
    position: np.ndarray
    stamp: float
    hits: int
    status: str = 'seen'          # seen, picking, on_plate, placed, delivered, failed, missed
    attempts: int = 0
    slot: int = -1
    failure: str = ''
    picked: bool = False          # lifted off the belt by the Zu 12
    last_seen: float = -math.inf  # when a frame last showed it
    unload_attempts: int = 0


@dataclass
class Motion:
    """A planned arm motion: its points, and the times of what happens on the way."""
    arm: str
    points: Points
    marks: Dict[str, float] = field(default_factory=dict)
    done: set = field(default_factory=set)

    @property
    def end(self) -> float:
        return self.points[-1][0]

    @property
    def goal(self) -> np.ndarray:
        return self.points[-1][1]

    def due(self, mark: str, now: float) -> bool:
        """True once when ``now`` reaches the mark's time."""
        if mark in self.marks and mark not in self.done and now >= self.marks[mark]:
            self.done.add(mark)
            return True
        return False


@dataclass
class RunResult:
    status: str                        # completed, incomplete, timeout, node_timeout, error
    completion_time: float             # sim time from start to both robots home [s]
    total: int
    identified: int                    # materials the vision reported with a colour
    picked: int                        # materials the Zu 12 lifted off the belt
    delivered: int                     # materials at their destination (as the machine saw it)
    grasp_attempts: int
    grasp_successes: int
    missed: int                        # went off the belt end unpicked
    failed: int
    message: str = ''
    materials: List[Dict] = field(default_factory=list)


class Pipeline:
    """The whole run. Call ``tick(observation)`` every control period until ``finished``."""

    def __init__(self, layout: CellLayout, ports: Ports, settings: Settings = Settings(),
                 start_time: float = 0.0) -> None:
        self.layout, self.ports, self.s = layout, ports, settings
        self.start_time = start_time
        self.events: List[Event] = []
        self.materials: Dict[int, Material] = {}
        self.loader_state = 'start'
        self.transport_state = 'wait_load'
        self.result: Optional[RunResult] = None
        self.grasp_attempts = self.grasp_successes = 0
        self._deadline: Dict[str, float] = {}
        self._motion: Dict[str, Optional[Motion]] = {'zu12': None, 'youbot': None}
        self._belt_running = False
        self._belt_log: List[Tuple[float, bool]] = [(start_time, False)]
        self._now = start_time
        self._next_slot = 0
        self._pick: Optional[Material] = None
        self._unload: List[Material] = []
        self._follower: Optional[PathFollower] = None
        self._drive_goal = ''
        self._home_q: Dict[str, np.ndarray] = {}
        self._done_time: Optional[float] = None

    # --- the loop -----------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        return self.result is not None

    def tick(self, obs: Observation) -> None:
        if self.finished:
            return
        self._now, self._q_now = obs.now, obs.zu12_q
        try:
            if self.loader_state == 'start':
                self._start(obs)
            self._see(obs)
            getattr(self, '_loader_' + self.loader_state)(obs)
            self._belt(obs.now, self._belt_wanted(obs.now))
            getattr(self, '_transport_' + self.transport_state)(obs)
            if obs.now - self.start_time > self.s.run_timeout:
                self._finish(obs.now, 'timeout', f'the run took over {self.s.run_timeout} s')
            elif self.loader_state == 'done' and self.transport_state == 'done':
                complete = all(m.status in ('placed', 'delivered')
                               for m in self.materials.values())
                complete = complete and len(self.materials) == self.layout.total
                self._finish(obs.now, 'completed' if complete else 'incomplete', '')
        except NodeTimeout as exc:
            self._finish(obs.now, 'node_timeout', str(exc))

    def abort(self, now: float, status: str, message: str) -> None:
        """End the run from outside (the node lost its simulator, or was interrupted)."""
        if not self.finished:
            self._finish(now, status, message)

    # --- helpers ------------------------------------------------------------------------------
    def _event(self, now: float, kind: str, robot: str = '', m: Optional[Material] = None,
               detail: str = '') -> None:
        e = Event(now, kind, robot, m.id if m else -1, m.color if m else '', detail)
        self.events.append(e)
        self.ports.event(e)

    def _set_state(self, machine: str, state: str, now: float, budget: float) -> None:
        setattr(self, f'{machine}_state', state)
        self._deadline[machine] = now + budget
        self._event(now, 'state', machine, detail=state)

    def _late(self, machine: str, now: float) -> bool:
        return now > self._deadline.get(machine, math.inf)

    def _belt(self, now: float, running: bool) -> None:
        if running != self._belt_running:
            effective = self.ports.belt(self.layout.belt_speed if running else 0.0)
            self._belt_running = running
            self._belt_log.append((max(now, effective or now), running))
            self._event(now, 'belt_started' if running else 'belt_stopped')

    def _send(self, motion: Motion) -> None:
        self._motion[motion.arm] = motion
        self.ports.trajectory(motion.arm, motion.points)

    def _belt_wanted(self, now: float) -> bool:
        """The belt runs while loading, except while a material waits at the pick point or the
        cup is on one still on the belt: nothing passes the pick point unnoticed."""
        if self.loader_state in ('home', 'done'):
            return False
        if self.loader_state == 'pick' and self._pick is not None and not (
                self._pick.picked and self._arrived('zu12', self._q_now, now)):
            return False
        return not any(self._belt_x(m, now) >= self.s.pick_x
                       for m in self.materials.values() if m.status == 'seen')

    def _arrived(self, arm: str, q: np.ndarray, now: float) -> Optional[bool]:
        """After a motion's end: True when the arm is at its goal, None while it may still get
        there, False once it is later than the settle margin (a stalled arm)."""
        motion = self._motion[arm]
        if motion is None or now < motion.end:
            return None
        if float(np.max(np.abs(q - motion.goal))) <= self.s.arrive_tolerance:
            return True
        return False if now > motion.end + self.s.settle_margin else None

    def _fail(self, now: float, m: Material, kind: str, why: str, robot: str) -> None:
        m.status, m.failure = ('missed' if kind == 'missed' else 'failed'), why
        self._event(now, kind, robot, m, why)

    def _finish(self, now: float, status: str, message: str) -> None:
        # Leave nothing moving.
        for call in (lambda: self.ports.drive(0.0, 0.0, 0.0), lambda: self.ports.belt(0.0)):
            try:
                call()
            except NodeTimeout:
                pass
        mats = list(self.materials.values())
        self.result = RunResult(
            status=status, completion_time=now - self.start_time, total=self.layout.total,
            identified=len(mats),
            picked=sum(1 for m in mats if m.picked),
            delivered=sum(1 for m in mats if m.status in ('placed', 'delivered')),
            grasp_attempts=self.grasp_attempts, grasp_successes=self.grasp_successes,
            missed=sum(1 for m in mats if m.status == 'missed'),
            failed=sum(1 for m in mats if m.status == 'failed'), message=message,
            materials=[{'id': m.id, 'color': m.color, 'status': m.status,
                        'attempts': m.attempts, 'unload_attempts': m.unload_attempts,
                        'failure': m.failure} for m in mats])
        self._event(now, 'finished', detail=f'{status}{": " + message if message else ""}')

    # --- perception ---------------------------------------------------------------------------
    def _see(self, obs: Observation) -> None:
        for d in obs.detections:
            m = self.materials.get(d.id)
            if m is None:
                if d.hits < self.s.confirm_hits:
                    continue
                m = self.materials[d.id] = Material(d.id, d.color, np.asarray(d.position, float),
                                                    d.stamp, d.hits)
                self._event(obs.now, 'seen', 'vision', m,
                            f'at {np.round(m.position, 3).tolist()}')
            elif m.status == 'seen':
                m.position, m.stamp, m.hits = np.asarray(d.position, float), d.stamp, d.hits
            m.last_seen = obs.now
        # A material still on the belt that has gone past its end was not picked.
        for m in self.materials.values():
            if m.status == 'seen' and self._belt_x(m, obs.now) > self.layout.belt_end_x:
                self._fail(obs.now, m, 'missed', 'went off the belt end unpicked', 'zu12')

    def _belt_x(self, m: Material, now: float) -> float:
        """Where a material on the belt is now: seen at its frame's time, carried since then
        for as long as the belt ran."""
        return m.position[0] + self.layout.belt_speed * self._running_time(m.stamp, now)

    def _running_time(self, t0: float, t1: float) -> float:
        total = 0.0
        log = self._belt_log + [(t1, self._belt_running)]
        for (start, running), (end, _) in zip(log, log[1:]):
            if running:
                total += max(0.0, min(end, t1) - max(start, t0))
        return total

    # --- loader: the Zu 12 --------------------------------------------------------------------
    def _start(self, obs: Observation) -> None:
        self._home_q = {'zu12': np.array(obs.zu12_q, float),
                        'youbot': np.array(obs.youbot_q, float)}
        self._set_state('loader', 'wait', obs.now, self.s.idle_timeout)

    def _loader_wait(self, obs: Observation) -> None:
        now = obs.now
        waiting = [m for m in self.materials.values() if m.status == 'seen']
        accounted = sum(1 for m in self.materials.values() if m.status != 'seen')
        if accounted >= self.layout.total or (not waiting and self._late('loader', now)):
            why = ('every material handled' if accounted >= self.layout.total else
                   f'nothing new for {self.s.idle_timeout:.0f} s')
            self._event(now, 'loading_over', 'zu12', detail=why)
            self._plan_home('zu12', obs)
            self._set_state('loader', 'home', now, self._motion['zu12'].end - now
                            + self.s.settle_margin)
            return
        if self._motion['zu12'] is not None and now < self._motion['zu12'].end:
            return                                   # still rising from the last place
        front = max(waiting, key=lambda m: self._belt_x(m, now), default=None)
        if front is None:
            return
        x = self._belt_x(front, now)
        if x < self.s.pick_x or self._belt_running:
            return                  # (picked once the belt rule has stopped it, at a known x)
        stopped = self._belt_log[-1][0]
        if stopped - front.last_seen < VIEW_GAP_S and now - stopped < STOP_FRAME_WAIT_S:
            # Still in the camera's view: use its frames at rest (in real time the belt stops
            # a little later than decided, by an unknown delay below this wait).
            return
        if front.stamp < stopped:
            front.position = np.array([x, front.position[1], front.position[2]])
        front.stamp = now
        self._pick = front
        front.status = 'picking'
        self._plan_pick(obs, front)

    def _plan_pick(self, obs: Observation, m: Material) -> None:
        now, t = obs.now, self.s.timing
        size = self.layout.material_size
        # A second attempt presses 4 mm further down.
        timing = PickTiming(**{**t.__dict__, 'contact_gap': t.contact_gap - 0.004 * m.attempts})
        seed = self._home_q['zu12']
        hover = m.position + np.array([0.0, 0.0, size / 2 + timing.hover])
        q_hover = self._solve('zu12', hover, DOWN, 'world', seed)
        if q_hover is None:
            return self._pick_failed(obs, m, 'no IK solution for the pick')
        lead = motion_duration(obs.zu12_q, q_hover, self._limits('zu12'), self.s.zu12_scaling,
                               0.5) + 0.1 + self.s.plan_latency
        waypoints, t_arm = pick_waypoints(m.position, now, (0.0, 0.0, 0.0),
                                          now + lead + timing.descend, size, timing)
        points = self._solve_path('zu12', waypoints, q_hover)
        if points is None:
            return self._pick_failed(obs, m, 'no IK solution for the pick path')
        t_contact = now + lead + timing.descend
        self._send(Motion('zu12', points, {'arm': waypoints[1][0],
                                           'check': t_contact + timing.dwell}))
        m.attempts += 1
        self.grasp_attempts += 1
        self._set_state('loader', 'pick', now, points[-1][0] - now + self.s.settle_margin)

    def _pick_failed(self, obs: Observation, m: Material, why: str) -> None:
        self._fail(obs.now, m, 'grasp_failed', why, 'zu12')
        self._pick = None
        self._plan_home('zu12', obs, ready=True)
        self._set_state('loader', 'retreat', obs.now,
                        self._motion['zu12'].end - obs.now + self.s.settle_margin)

    def _loader_pick(self, obs: Observation) -> None:
        m, motion, now = self._pick, self._motion['zu12'], obs.now
        if motion.due('arm', now):
            self.ports.grip('zu12', True)
        if motion.due('check', now):
            if obs.zu12_holding:
                self.grasp_successes += 1
                m.picked = True
                self._event(now, 'picked', 'zu12', m, f'attempt {m.attempts}')
            else:
                self.ports.grip('zu12', False)
                self._event(now, 'grasp_missed', 'zu12', m, f'attempt {m.attempts}')
                if m.attempts <= self.s.max_retries:
                    return self._plan_pick(obs, m)
                return self._pick_failed(obs, m, f'not held after {m.attempts} attempts')
        if 'check' not in motion.done:
            return
        if not obs.zu12_holding:
            self.ports.grip('zu12', False)
            return self._pick_failed(obs, m, 'dropped while lifting')
        arrived = self._arrived('zu12', obs.zu12_q, now)
        if arrived is False or self._late('loader', now):
            return self._pick_failed(obs, m, 'the arm did not reach the lift point')
        if arrived:
            self._plan_place(obs, m)

    def _plan_place(self, obs: Observation, m: Material) -> None:
        now, size = obs.now, self.layout.material_size
        if m.color == 'purple':
            target = self.layout.ground_target
        else:
            if self._next_slot >= len(PLATE_SLOTS_IN_BASE_M):
                return self._pick_failed(obs, m, 'the youBot plate is full')
            m.slot = self._next_slot
            self._next_slot += 1
            target = slot_in_world(obs.youbot_pose, PLATE_SLOTS_IN_BASE_M[m.slot],
                                   self._youbot_base_z(), size)
        above = np.asarray(target) + np.array(
            [0.0, 0.0, size + self.s.timing.place_gap + self.s.timing.lift_height])
        seed = self._motion['zu12'].goal
        q_above = self._solve('zu12', above, DOWN, 'world', seed)
        if q_above is None:
            return self._place_failed(obs, m, 'no IK solution above the place')
        d = motion_duration(obs.zu12_q, q_above, self._limits('zu12'), self.s.zu12_scaling,
                            0.8) + self.s.plan_latency
        waypoints, t_release = place_waypoints(now + d, target, size, self.s.timing)
        points = self._solve_path('zu12', waypoints, q_above)
        if points is None:
            return self._place_failed(obs, m, 'no IK solution for the place path')
        self._send(Motion('zu12', points, {'release': t_release}))
        self._set_state('loader', 'place', now, points[-1][0] - now + self.s.settle_margin)

    def _place_failed(self, obs: Observation, m: Material, why: str) -> None:
        self.ports.grip('zu12', False)
        self._pick_failed(obs, m, why)

    def _loader_place(self, obs: Observation) -> None:
        m, motion, now = self._pick, self._motion['zu12'], obs.now
        if 'release' not in motion.done and not obs.zu12_holding:
            return self._place_failed(obs, m, 'dropped on the way to its place')
        if motion.due('release', now):
            ok, why = self.ports.grip('zu12', False)
            if not ok:
                return self._place_failed(obs, m, f'release failed: {why}')
            if m.color == 'purple':
                m.status = 'placed'
                self._event(now, 'placed', 'zu12', m, 'ground target')
            else:
                m.status = 'on_plate'
                self._event(now, 'loaded', 'zu12', m, f'plate slot {m.slot}')
        arrived = self._arrived('zu12', obs.zu12_q, now)
        if arrived is False or self._late('loader', now):
            self._event(now, 'arm_stalled', 'zu12', m, 'did not rise from the place')
            self._plan_home('zu12', obs, ready=True)
            self._set_state('loader', 'retreat', now,
                            self._motion['zu12'].end - now + self.s.settle_margin)
        elif arrived:
            self._pick = None
            self._set_state('loader', 'wait', now, self.s.idle_timeout)

    def _loader_retreat(self, obs: Observation) -> None:
        if self._motion_over('loader', 'zu12', obs, 'retreat'):
            self._set_state('loader', 'wait', obs.now, self.s.idle_timeout)

    def _loader_home(self, obs: Observation) -> None:
        if self._motion_over('loader', 'zu12', obs, 'home'):
            self._set_state('loader', 'done', obs.now, math.inf)

    def _motion_over(self, machine: str, arm: str, obs: Observation, what: str) -> bool:
        """Whether an arm's last motion is over: arrived, or past its state's deadline (then
        reported as stalled)."""
        q = obs.zu12_q if arm == 'zu12' else obs.youbot_q
        arrived = self._arrived(arm, q, obs.now)
        if arrived is None and not self._late(machine, obs.now):
            return False
        if not arrived:
            self._event(obs.now, 'arm_stalled', arm, detail=f'{what} not reached')
        return True

    def _loader_done(self, obs: Observation) -> None:
        pass

    def _plan_home(self, arm: str, obs: Observation, ready: bool = False) -> None:
        q = obs.zu12_q if arm == 'zu12' else obs.youbot_q
        goal = self._home_q[arm]
        d = motion_duration(q, goal, self._limits(arm), self._scaling(arm),
                            0.5) + self.s.plan_latency
        self._send(Motion(arm, [(obs.now + d, goal.copy())]))
        if not ready:
            self._event(obs.now, 'returning', arm)

    # --- transport: the youBot ----------------------------------------------------------------
    def _transport_wait_load(self, obs: Observation) -> None:
        on_plate = [m for m in self.materials.values() if m.status == 'on_plate']
        loaded = len(on_plate) >= self.layout.plate_bound()
        if not (loaded or self.loader_state == 'done') or self.loader_state == 'place':
            return                      # (nor while the cup is still over the plate)
        self._unload = sorted(on_plate, key=lambda m: (m.color == 'blue', m.slot))
        if not self._unload:
            self._set_state('transport', 'done', obs.now, math.inf)
            return
        self._event(obs.now, 'departing', 'youbot', detail=f'{len(self._unload)} materials')
        self._drive_to(obs, self._stand_for(self._unload[0]))

    def _stand_for(self, m: Material) -> str:
        return 'platform_stand' if m.color == 'blue' else 'pool_stand'

    def _drive_to(self, obs: Observation, goal: str) -> None:
        lay = self.layout
        target = lay.youbot_home if goal == 'home' else getattr(lay, goal)
        start = tuple(obs.youbot_pose)
        via: Sequence = ()
        if goal == 'pool_stand' and np.hypot(start[0] - target[0], start[1] - target[1]) > 1.0:
            via = lay.via_out
        elif goal == 'home':
            via = lay.via_back
        path = BezierPath(key_poses_between(start, target, via))
        self._follower = PathFollower(path, obs.now, self.s.drive_speed, self.s.drive_accel)
        self._drive_goal = goal
        self._event(obs.now, 'driving', 'youbot', detail=f'to {goal}, {path.length:.2f} m')
        self._set_state('transport', 'drive', obs.now,
                        self._follower.profile.duration + self.s.drive_margin)

    def _transport_drive(self, obs: Observation) -> None:
        status = self._follower.update(obs.now, obs.youbot_pose, obs.youbot_velocity[:2],
                                       obs.youbot_velocity[2])
        self.ports.drive(*status.command)
        if status.finished or self._late('transport', obs.now):
            self.ports.drive(0.0, 0.0, 0.0)
            if not status.finished:
                self._event(obs.now, 'drive_stalled', 'youbot', detail=(
                    f'{status.position_error * 1000:.0f} mm from {self._drive_goal}'))
            self._event(obs.now, 'arrived', 'youbot', detail=self._drive_goal)
            if self._drive_goal == 'home':
                # Folded only at home: the folded arm reaches down in front of the base, where
                # the platform and what was just set on it are.
                self._plan_home('youbot', obs)
                return self._set_state('transport', 'fold', obs.now, self._motion['youbot'].end
                                       - obs.now + self.s.settle_margin)
            self._next_unload(obs)

    def _next_unload(self, obs: Observation) -> None:
        if not self._unload:
            q = np.asarray(obs.youbot_q, float)
            d = motion_duration(q, YOUBOT_CARRY_Q, self._limits('youbot'),
                                self.s.youbot_scaling, 0.5) + self.s.plan_latency
            self._send(Motion('youbot', [(obs.now + d, YOUBOT_CARRY_Q.copy())]))
            self._set_state('transport', 'stow', obs.now, d + self.s.settle_margin)
            return
        m = self._unload[0]
        here = self._drive_goal
        if self._stand_for(m) != here:
            return self._drive_to(obs, self._stand_for(m))
        self._plan_unload(obs, m)

    def _plan_unload(self, obs: Observation, m: Material) -> None:
        now, size, t = obs.now, self.layout.material_size, self.s.timing
        slot = PLATE_SLOTS_IN_BASE_M[m.slot]
        top = (PLATE_TOP_IN_BASE_M + size + YOUBOT_GRASP_STANDOFF_M
               - 0.004 * m.unload_attempts)
        contact = np.array([slot[0], slot[1], top])
        hover = contact + np.array([0.0, 0.0, 0.06])
        if m.color == 'blue':
            drop_world = self.layout.platform_place + np.array(
                [0.0, 0.0, size + t.place_gap + YOUBOT_GRASP_STANDOFF_M])
        else:
            drops = self.layout.pool_drops
            drop_world = drops[sum(1 for x in self.materials.values()
                                   if x.status == 'delivered' and x.color != 'blue')
                               % len(drops)]
        drop = world_to_base(obs.youbot_pose, drop_world)
        drop[2] -= self._youbot_base_z()
        plan = self._solve_tilted([hover, contact, hover, drop + np.array([0.0, 0.0, 0.05]),
                                   drop], np.array(obs.youbot_q, float))
        if plan is None:
            self._unload.pop(0)
            self._fail(now, m, 'grasp_failed', 'unload: no IK solution', 'youbot')
            return self._next_unload(obs)
        lim, sc = self._limits('youbot'), self.s.youbot_scaling
        t0 = now + motion_duration(obs.youbot_q, plan[0], lim, sc, 0.5) + self.s.plan_latency
        t1 = t0 + t.descend
        t2 = t1 + t.dwell
        t3 = t2 + t.lift
        t4 = t3 + motion_duration(plan[2], plan[3], lim, sc, 0.8)
        t5 = t4 + t.place_descend
        points = [(t0, plan[0]), (t1, plan[1]), (t2, plan[1].copy()), (t3, plan[2]),
                  (t4, plan[3]), (t5, plan[4]), (t5 + 0.3, plan[4].copy())]
        self._send(Motion('youbot', points, {'arm': (t0 + t1) / 2, 'check': t2,
                                             'release': t5 + 0.1}))
        m.unload_attempts += 1
        self.grasp_attempts += 1
        self._set_state('transport', 'unload', now, t5 + 0.3 - now + self.s.settle_margin)

    def _transport_unload(self, obs: Observation) -> None:
        m, motion, now = self._unload[0], self._motion['youbot'], obs.now
        if motion.due('arm', now):
            self.ports.grip('youbot', True)
        if motion.due('check', now):
            if obs.youbot_holding:
                self.grasp_successes += 1
                self._event(now, 'unload_grasped', 'youbot', m,
                            f'attempt {m.unload_attempts}')
            else:
                self.ports.grip('youbot', False)
                self._event(now, 'grasp_missed', 'youbot', m,
                            f'attempt {m.unload_attempts}')
                if m.unload_attempts <= self.s.max_retries:
                    return self._plan_unload(obs, m)
                self._unload.pop(0)
                self._fail(now, m, 'grasp_failed', f'unload: not held after '
                           f'{m.unload_attempts} attempts', 'youbot')
                return self._next_unload(obs)
        if 'check' in motion.done and 'release' not in motion.done and not obs.youbot_holding:
            self.ports.grip('youbot', False)
            self._unload.pop(0)
            self._fail(now, m, 'failed', 'unload: dropped on the way', 'youbot')
            return self._next_unload(obs)
        if motion.due('release', now):
            self.ports.grip('youbot', False)
            m.status = 'delivered'
            self._event(now, 'delivered', 'youbot', m, self.layout.destination(m.color))
        arrived = self._arrived('youbot', obs.youbot_q, now)
        if arrived is False or (arrived is None and self._late('transport', now)):
            self._event(now, 'arm_stalled', 'youbot', m, 'unload motion not completed')
            arrived = True
        if arrived:
            self._unload.pop(0)
            self._next_unload(obs)

    def _transport_stow(self, obs: Observation) -> None:
        if self._motion_over('transport', 'youbot', obs, 'carry pose'):
            self._drive_to(obs, 'home')

    def _transport_fold(self, obs: Observation) -> None:
        if self._motion_over('transport', 'youbot', obs, 'home pose'):
            self._set_state('transport', 'done', obs.now, math.inf)

    def _transport_done(self, obs: Observation) -> None:
        pass

    # --- kinematics through the port ----------------------------------------------------------
    def _solve(self, arm: str, position, orientation, frame: str, seed) -> Optional[np.ndarray]:
        q, why = self.ports.solve(arm, position, orientation, frame, seed)
        if q is None:
            self._event(self._now, 'ik_failed', arm,
                        detail=f'{np.round(position, 3).tolist()}: {why}')
        return q

    def _solve_path(self, arm: str, waypoints, seed) -> Optional[Points]:
        points = []
        for t, p in waypoints:
            q = self._solve(arm, p, DOWN, 'world', seed)
            if q is None:
                return None
            points.append((t, q))
            seed = q
        return points

    def _solve_tilted(self, points: Sequence[np.ndarray], seed: np.ndarray
                      ) -> Optional[List[np.ndarray]]:
        """Joint positions for a youBot path whose every point has the same tool tilt: its arm
        reaches the plate's far slots only leaning outwards, and a material held at one tilt
        stays level only if it is set down at the same tilt."""
        for tilt_deg in range(0, 90, 10):
            plan, q = [], seed
            for p in points:
                q, _ = self.ports.solve('youbot', p, youbot_tool_quaternion(
                    p, math.radians(tilt_deg)), 'base_link', q)
                if q is None:
                    break
                plan.append(q)
            if len(plan) == len(points):
                return plan
        self._event(self._now, 'ik_failed', 'youbot',
                    detail=f'{np.round(points[1], 3).tolist()} via '
                           f'{np.round(points[-1], 3).tolist()} at any one tilt up to 80 deg')
        return None

    def _limits(self, arm: str) -> np.ndarray:
        if arm == 'zu12':
            from controllers.zu12_arm import JOINT_VELOCITY_LIMITS
            return np.asarray(JOINT_VELOCITY_LIMITS)
        from controllers.youbot_arm import JOINT_VELOCITY_LIMIT
        return np.full(5, JOINT_VELOCITY_LIMIT)

    def _scaling(self, arm: str) -> float:
        return self.s.zu12_scaling if arm == 'zu12' else self.s.youbot_scaling

    def _youbot_base_z(self) -> float:
        return YOUBOT_BASE_Z_M


# base_link's height above the floor when the youBot stands on its wheels [m].
YOUBOT_BASE_Z_M = 0.0815
# The youBot's arm upright (the datasheet's candle pose) while the base drives home.
YOUBOT_CARRY_Q = np.zeros(5)
# The youBot's fingertips reach 10.4 mm beyond gripper_tcp: it grasps a material's top face with
# the TCP this far above it, so that the fingertips do not push the material away.
YOUBOT_GRASP_STANDOFF_M = 0.0104 + 0.002


def youbot_tool_quaternion(p: Sequence[float], tilt: float) -> Tuple[float, float, float, float]:
    """Tool orientation (x, y, z, w in base_link) for the youBot's 5-joint arm at ``p``: the
    approach axis down, leaning ``tilt`` away from the arm's base axis in the arm's vertical
    plane (the only orientations a 5-joint arm reaches at an arbitrary point)."""
    from controllers.transforms import matrix_to_quaternion
    phi = math.atan2(p[1] - ARM_BASE_IN_BASE_LINK_M[1], p[0] - ARM_BASE_IN_BASE_LINK_M[0])
    z = np.array([math.cos(phi) * math.sin(tilt), math.sin(phi) * math.sin(tilt),
                  -math.cos(tilt)])
    y = np.array([-math.sin(phi), math.cos(phi), 0.0])
    x = np.cross(y, z)
    return matrix_to_quaternion(np.column_stack([x, y, z]))
