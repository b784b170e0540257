"""The whole run: the two machines and what they share."""
from __future__ import annotations

import math
from typing import (
    Dict,
    List,
    Optional,
    Sequence,
)

import numpy as np

from controllers import youbot_arm, zu12_arm
from controllers.arrays import Vector
from controllers.time_optimal import (
    SAMPLE_PERIOD_S,
    JointLimits,
    Waypoint,
    plan,
)
from coordinator.layout import (
    CellLayout,
)
from coordinator.pipeline.belt import BeltModel
from coordinator.pipeline.loader import Loader
from coordinator.pipeline.model import (
    DOWN,
    QUEUE_MARGIN_M,
    SET_DOWN_CLEARANCE_M,
    Event,
    EventKind,
    LoaderState,
    Material,
    MaterialStatus,
    Motion,
    NodeTimeout,
    Observation,
    Points,
    Ports,
    RunResult,
    Settings,
    Tally,
    TransportState,
    known,
)
from coordinator.pipeline.transport import Transport
from coordinator.reach import youbot_holds, youbot_tool_quaternion

# Materials not to come any more: on the plate, at their destination, or given up.
_PAST_THE_BELT = (MaterialStatus.ON_PLATE, MaterialStatus.PLACED, MaterialStatus.DELIVERED,
                  MaterialStatus.FAILED, MaterialStatus.MISSED)


class Pipeline:
    """The whole run: the two machines and what they share (materials, belt, arm motions,
    events, the ports). Call ``tick(observation)`` every control period until ``finished``."""

    def __init__(self, layout: CellLayout, ports: Ports, settings: Optional[Settings] = None,
                 start_time: float = 0.0, belt_ran_before: bool = False) -> None:
        """``belt_ran_before``: the belt was already running at the layout's speed when the
        run started (a real-time simulator started with its belt on, the coordinator later):
        what a frame showed before the start has ridden on since."""
        self.layout, self.ports, self.s = layout, ports, settings or Settings()
        self.start_time = start_time
        self.events: List[Event] = []
        self.materials: Dict[int, Material] = {}
        self.result: Optional[RunResult] = None
        self.grasps = {'zu12': [0, 0], 'youbot': [0, 0]}     # attempts, successes
        self.loaded = 0
        self.motions: Dict[str, Optional[Motion]] = {'zu12': None, 'youbot': None}
        self.belt = BeltModel(layout, self.materials, start_time, belt_ran_before)
        self.lag = 0.0                    # the longest a pick's plan has taken (real time) [s]
        self.belt_stops = 0               # the belt stopped while loading (its queue full)
        self.now = start_time
        self.home_q: Dict[str, np.ndarray] = {}
        self.loader = Loader(self)
        self.transport = Transport(self)

    # --- the loop -----------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        return self.result is not None

    def tick(self, obs: Observation) -> None:
        if self.finished:
            return
        self.now = obs.now
        self.belt.now = obs.now
        try:
            if self.loader.state is LoaderState.START:
                self.loader.start(obs)
            self._see(obs)
            self.loader.tick(obs)
            self._belt(obs.now, self._belt_wanted(obs.now))
            self.transport.tick(obs)
            if obs.now - self.start_time > self.s.run_timeout:
                self._finish(obs.now, 'timeout', f'the run took over {self.s.run_timeout} s')
            elif (self.loader.state is LoaderState.DONE
                  and self.transport.state is TransportState.DONE):
                complete = all(m.status.done
                               for m in self.materials.values())
                complete = complete and len(self.materials) == self.layout.total
                self._finish(obs.now, 'completed' if complete else 'incomplete', '')
        except NodeTimeout as exc:
            self._finish(obs.now, 'node_timeout', str(exc))

    def tally(self) -> Tally:
        """The materials' counts now (the result's, and the published state's)."""
        return Tally.of(list(self.materials.values()), self.layout.total)

    def abort(self, now: float, status: str, message: str) -> None:
        """End the run from outside (the node lost its simulator, or was interrupted)."""
        if not self.finished:
            self._finish(now, status, message)

    @property
    def grasp_attempts(self) -> int:
        return sum(a for a, _ in self.grasps.values())

    @property
    def grasp_successes(self) -> int:
        return sum(s for _, s in self.grasps.values())

    # --- what the machines share (coordinator.pipeline.shared lists it) -------------------------
    @property
    def loader_done(self) -> bool:
        return self.loader.state is LoaderState.DONE

    def zu12_clear_of_the_plate(self, now: float) -> bool:
        return self.loader.clear_of_the_plate(now)

    def count_grasp(self, arm: str, success: bool = False) -> None:
        self.grasps[arm][1 if success else 0] += 1

    def event(self, now: float, kind: EventKind, robot: str = '', m: Optional[Material] = None,
              detail: str = '') -> None:
        e = Event(now, kind, robot, m.id if m else -1, m.color if m else '', detail)
        self.events.append(e)
        self.ports.event(e)

    def send(self, motion: Motion, start: Optional[float] = None) -> None:
        """Send an arm motion planned now, its first segment starting after the plan latency
        (the convention of every plan here) or at ``start``; the port may schedule it later,
        whole."""
        motion.start = self.now + self.s.plan_latency if start is None else start
        delay = self.ports.trajectory(motion.arm, motion.points, motion.start)
        if delay:
            motion.delay(delay)
        self.motions[motion.arm] = motion

    def send_continuing(self, arm: str, now: float, t1: float, points: Points) -> None:
        """Replace the arm's running motion from its sample at ``t1`` on by ``points`` (which
        begin there, in that sample's state). The message repeats the motion's own samples
        between ``now`` and ``t1`` and is stamped ``now``: the controller, which skips the
        points already past when it takes it, joins it from where the running motion has the
        arm, whenever it arrives. (A new motion starts in the future, from rest: a controller
        holds its position until then, and from there a point of a motion it was following
        is out of reach; nor may the port delay it, which would tear it off that motion.)"""
        kept = [p for p in self.motion(arm).points if now < p[0] < t1 - 1e-9]
        motion = Motion(arm, kept + list(points), start=now)
        self.ports.trajectory(arm, motion.points, now, continuing=True)
        self.motions[arm] = motion

    def has_motion(self, arm: str) -> bool:
        return self.motions[arm] is not None

    def motion(self, arm: str) -> Motion:
        """The arm's current motion (one has been sent)."""
        return known(self.motions[arm], f'a motion of the {arm}')

    def arrived(self, arm: str, q: np.ndarray, now: float,
                dq: Optional[np.ndarray] = None) -> Optional[bool]:
        """After a motion's end: True when the arm is at its goal and at rest (``dq``, the
        measured joint velocities, if known), None while it may still get there, False once it
        is later than the settle margin (a stalled arm). At rest matters when the simulator took
        the motion in late: at its planned end the arm is then still moving, near its goal."""
        motion = self.motions[arm]
        if motion is None or now < motion.end:
            return None
        if (float(np.max(np.abs(q - motion.goal))) <= self.s.arrive_tolerance
                and (dq is None or float(np.max(np.abs(dq))) <= self.s.rest_speed)):
            return True
        return False if now > motion.end + self.s.settle_margin else None

    def fail(self, now: float, m: Material, kind: EventKind, why: str, robot: str) -> None:
        m.status = MaterialStatus.MISSED if kind is EventKind.MISSED else MaterialStatus.FAILED
        m.failure = why
        self.event(now, kind, robot, m, why)

    def plan_home(self, arm: str, obs: Observation, ready: bool = False) -> None:
        q = obs.zu12_q if arm == 'zu12' else obs.youbot_q
        self.send(Motion(arm, self.plan(arm, q, [Waypoint(self.home_q[arm].copy())])))
        if not ready:
            self.event(obs.now, EventKind.RETURNING, arm)

    def to_come(self, name: str) -> int:
        """Materials of class ``name`` the batch still brings that are not on the plate yet,
        nor placed, delivered or given up (nor being picked for a plate slot kept for it)."""
        gone = sum(1 for m in self.materials.values() if m.color == name and (
            m.status in _PAST_THE_BELT
            or (m.status == MaterialStatus.PICKING and m.slot >= 0)))
        return max(0, self.layout.manifest.get(name, 0) - gone)

    def to_come_counts(self) -> Dict[str, int]:
        return {c: self.to_come(c) for c in self.layout.manifest}

    def carried_to_come(self) -> int:
        """Carried materials the youBot has still to take (not on its plate yet)."""
        return sum(self.to_come(c) for c in self.layout.manifest if self.layout.carried(c))

    def plate_taken(self, but: Optional[Material] = None) -> Dict[int, str]:
        """The plate's slots that a material is on, or kept for one being picked, or where one
        the youBot failed to unload may still stand."""
        return {x.slot: x.color for x in self.materials.values()
                if x.slot >= 0 and x is not but
                and (x.status in (MaterialStatus.PICKING, MaterialStatus.ON_PLATE)
                     or x.left_on_plate)}

    def plate_slots(self, m: Material) -> List[int]:
        """The plate slots free for ``m`` now, in the order they are filled: for a pool
        material, only in a row whose stand has a drop spot left for it."""
        taken = self.plate_taken(m)
        free = self.layout.free_slots(m.color, taken, self.to_come_counts())
        if not self.layout.region_of(m.color).drop:
            return free
        room = {}
        for st in self.layout.stands:
            bound = sum(1 for k, c in taken.items() if self.layout.slot_row(k) == st.row
                        and self.layout.region_of(c).drop)
            room[st.row] = len(st.drops) - len(self.transport.dropped(st.name)) - bound
        return [k for k in free if room.get(self.layout.slot_row(k), 0) > 0]

    def loadable(self, m: Material) -> bool:
        """Whether the Zu 12 may put ``m`` onto the youBot's plate now: it waits at home, and
        has a slot for it."""
        return self.transport.loading and bool(self.plate_slots(m))

    def free_places(self, region: str, m: Material) -> List[int]:
        """The slots of a destination (its Region's, in order) that no other material has or
        is kept for: a material never goes down on another."""
        taken = {x.place for x in self.materials.values()
                 if x is not m and x.place >= 0
                 and x.status not in (MaterialStatus.FAILED, MaterialStatus.MISSED)
                 and self.layout.destination(x.color) == region}
        slots = self.layout.regions[region].slots
        return [k for k in range(len(slots)) if k not in taken]

    def set_down_rise(self, destination: Optional[str]) -> float:
        """How far over its release point a held material must swing in to a set-down on
        ``destination`` (None: the youBot's plate) to clear the materials there already by
        SET_DOWN_CLEARANCE_M (0: none there)."""
        there = [x.size for x in self.materials.values()
                 if (x.on_the_plate if destination is None else
                     x.status in (MaterialStatus.PLACED, MaterialStatus.DELIVERED)
                     and self.layout.destination(x.color) == destination)]
        if not there:
            return 0.0
        return max(there) + SET_DOWN_CLEARANCE_M - self.s.timing.place_gap

    # --- the belt -----------------------------------------------------------------------------
    def _belt(self, now: float, running: bool) -> None:
        if running != self.belt.running:
            effective = self.ports.belt(self.layout.belt_speed if running else 0.0)
            self.belt.switched(now, running, effective or now)
            loading = self.loader.state not in (LoaderState.HOME, LoaderState.DONE)
            why = ''
            if not running and loading:
                self.belt_stops += 1            # (stopped for the queue, not at the end)
                why = ('a lift out of the end stop\'s queue' if self.loader.pauses_belt(now)
                       else 'the queue would overflow the belt')
            self.event(now, EventKind.BELT_STARTED if running else EventKind.BELT_STOPPED,
                       detail=why)

    def _belt_wanted(self, now: float) -> bool:
        """The belt runs at a uniform speed from the start until loading is over, unless what
        waits for the youBot would overflow it: the end stop's queue reaching back to the pick
        point, or (without a stop) a material the Zu 12 cannot take now near the belt's end."""
        if self.loader.state in (LoaderState.HOME, LoaderState.DONE):
            return False
        return not (self.loader.pauses_belt(now) or self._overflow())

    def _overflow(self) -> bool:
        if self.layout.end_stop:
            return self.belt.queue_tail() < self.s.pick_x + QUEUE_MARGIN_M
        end = self.layout.belt_end_x - QUEUE_MARGIN_M
        return any(m.status is MaterialStatus.SEEN and m.position[0] + m.size / 2 > end
                   and self.layout.carried(m.color) and not self.loadable(m)
                   for m in self.belt.on_belt())

    # --- perception ---------------------------------------------------------------------------
    def _see(self, obs: Observation) -> None:
        self.belt.advance(obs.now)
        for d in obs.detections:
            m = self.materials.get(d.id)
            if m is None:
                if (d.hits < self.s.confirm_hits or not self._on_belt_area(d.position)
                        or d.position[0] >= self.s.pick_x):
                    continue
                if d.color not in self.layout.rules:
                    continue                # (no class of this cell: the vision's config)
                m = self.materials[d.id] = Material(d.id, d.color, self.belt.seen_at(d, obs.now),
                                                    obs.now, d.hits, detection=d,
                                                    size=self.layout.size_of(d.color))
                self.event(obs.now, EventKind.SEEN, 'vision', m,
                           f'at {np.round(m.position, 3).tolist()}')
            elif m.status == MaterialStatus.SEEN:
                m.position, m.stamp, m.hits = self.belt.seen_at(d, obs.now), obs.now, d.hits
            m.last_seen = obs.now
        # Without an end stop, a material still on the belt past its end was not picked.
        for m in self.materials.values():
            if (m.status == MaterialStatus.SEEN and not self.layout.end_stop
                    and m.position[0] > self.layout.belt_end_x):
                self.fail(obs.now, m, EventKind.MISSED, 'went off the belt end unpicked', 'zu12')

    def _on_belt_area(self, position: Vector) -> bool:
        """Whether a detection lies on the belt. The camera also sees beside it, and downstream
        of the pick point, where the Zu 12 lifts materials and carries them to their places: a
        material in the cup is not a new one. A new material is confirmed where it enters the
        view, upstream of the pick point (``_see``)."""
        return bool(abs(position[1] - self.layout.belt_y) <= self.layout.belt_width / 2)

    # --- the end ------------------------------------------------------------------------------
    def _finish(self, now: float, status: str, message: str) -> None:
        # Leave nothing moving.
        for call in (lambda: self.ports.follow(None), lambda: self.ports.drive(0.0, 0.0, 0.0),
                     lambda: self.ports.belt(0.0)):
            try:
                call()
            except NodeTimeout:
                pass
        mats = list(self.materials.values())
        tally = self.tally()
        self.result = RunResult(
            status=status, completion_time=now - self.start_time, total=tally.total,
            identified=tally.identified, picked=tally.picked, delivered=tally.delivered,
            grasp_attempts=self.grasp_attempts, grasp_successes=self.grasp_successes,
            zu12_grasp_attempts=self.grasps['zu12'][0],
            zu12_grasp_successes=self.grasps['zu12'][1],
            youbot_grasp_attempts=self.grasps['youbot'][0],
            youbot_grasp_successes=self.grasps['youbot'][1], loaded=self.loaded,
            trips=self.transport.trips, belt_stops=self.belt_stops,
            missed=tally.missed, failed=tally.failed, message=message,
            materials=[{'id': m.id, 'color': m.color, 'status': m.status.value,
                        'attempts': m.attempts, 'unload_attempts': m.unload_attempts,
                        'failure': m.failure} for m in mats])
        self.event(now, EventKind.FINISHED, detail=f'{status}{": " + message if message else ""}')

    # --- kinematics through the port ----------------------------------------------------------
    def solve(self, arm: str, position: Vector, orientation: Vector, frame: str,
              seed: Vector) -> Optional[np.ndarray]:
        q, why = self.ports.solve(arm, position, orientation, frame, seed)
        if q is None:
            self.event(self.now, EventKind.IK_FAILED, arm,
                       detail=f'{np.round(position, 3).tolist()}: {why}')
        return q

    def solve_path(self, arm: str, positions: Sequence[Vector],
                   seed: Vector) -> Optional[List[np.ndarray]]:
        """Joint positions for the tool pointing down at each of ``positions`` (world), each
        seeded with the one before; None if any has no solution."""
        qs = []
        for p in positions:
            q = self.solve(arm, p, DOWN, 'world', seed)
            if q is None:
                return None
            qs.append(q)
            seed = q
        return qs

    def solve_tilted(self, points: Sequence[np.ndarray], seed: np.ndarray,
                     payload: float = 0.0, held_from: int = 0) -> Optional[List[np.ndarray]]:
        """Joint positions for a youBot path whose every point has the same tool tilt: its arm
        reaches the plate's far slots only leaning outwards, and a material held at one tilt
        stays level only if it is set down at the same tilt. From point ``held_from`` on the
        arm holds ``payload`` kg: a tilt whose poses there its joints cannot hold at rest
        (youbot_holds) is not taken."""
        heavy = False
        for tilt_deg in range(0, 90, 10):
            plan: List[np.ndarray] = []
            q = seed
            for p in points:
                solution, _ = self.ports.solve('youbot', p, youbot_tool_quaternion(
                    p, math.radians(tilt_deg)), 'base_link', q)
                if solution is None:
                    break
                q = solution
                plan.append(q)
            if len(plan) == len(points):
                if youbot_holds(plan[held_from:], payload):
                    return plan
                heavy = True
        why = (f'not held at rest with {payload} kg' if heavy else 'at any one tilt up to 80 deg')
        self.event(self.now, EventKind.IK_FAILED, 'youbot',
                   detail=f'{np.round(points[1 if len(points) > 1 else 0], 3).tolist()} via '
                          f'{np.round(points[-1], 3).tolist()} {why}')
        return None

    def limits(self, arm: str) -> JointLimits:
        """The arm's joint limits, the velocity scaled by its setting."""
        if arm == 'zu12':
            limits = JointLimits(np.asarray(zu12_arm.JOINT_VELOCITY_LIMITS),
                                 np.asarray(zu12_arm.JOINT_ACCELERATION_LIMITS),
                                 np.asarray(zu12_arm.JOINT_JERK_LIMITS))
            return limits.scaled(self.s.zu12_scaling)
        return JointLimits(np.full(5, youbot_arm.JOINT_VELOCITY_LIMIT),
                           np.full(5, youbot_arm.JOINT_ACCELERATION_LIMIT),
                           np.full(5, youbot_arm.JOINT_JERK_LIMIT)).scaled(self.s.youbot_scaling)

    def plan(self, arm: str, q: Vector, waypoints: Sequence[Waypoint],
             wait: float = 0.0, start: Optional[float] = None) -> Points:
        """A time-optimal motion of ``arm`` from rest at ``q`` through ``waypoints``, starting
        ``wait`` after the plan latency from now (the convention of every plan here), or at
        ``start``."""
        t0 = self.now + self.s.plan_latency if start is None else start
        motion = plan(q, waypoints, self.limits(arm), t0 + wait)
        # The controller starts from where the arm is: the start sample is sent only as the end
        # of a wait (a hold at the current position).
        points = motion.points()
        if len(points) == 1:            # already there: hold it, a sample period on
            t, q, v, a = points[0]
            return [(t + SAMPLE_PERIOD_S, q, v, a)]
        return points[0 if wait > 0.0 else 1:]

    def arrival_time(self, arm: str, q: np.ndarray) -> float:
        """When the arm's current motion passes closest to ``q`` (as the port scheduled it)."""
        points = self.motion(arm).points
        return min(points, key=lambda p: float(np.max(np.abs(p[1] - q))))[0]
