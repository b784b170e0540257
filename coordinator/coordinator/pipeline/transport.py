"""The transport: the youBot carries its load to the pool and unloads it."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import (
    Any,
    Callable,
    List,
    Optional,
    Sequence,
    Tuple,
)

import numpy as np

from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.path_follower import PathFollower, PDGains, TurnLimits
from controllers.time_optimal import (
    PlanError,
    Waypoint,
    timed_path,
)
from coordinator.layout import (
    POOL,
    CellLayout,
    world_to_base,
)
from coordinator.pipeline.arm import YoubotArm
from coordinator.pipeline.machine import Machine, transition_table
from coordinator.pipeline.materials import MaterialBook
from coordinator.pipeline.model import (
    RELEASE_HOLD_S,
    SETTLE_S,
    SPRING_BACK_WAIT_S,
    EventKind,
    Material,
    MaterialStatus,
    Observation,
    Points,
    Ports,
    Settings,
    TransportState,
    known,
)
from coordinator.pipeline.record import EventLog
from coordinator.pipeline.unload_geometry import (
    DROP_REACH_TOLERANCE_M,
    YOUBOT_CARRY_Q,
    YOUBOT_GRASP_STANDOFF_M,
    clear_of_the_plate,
    grip_points,
    held_offset,
    short_of,
)
from coordinator.reach import YOUBOT_LOAD_MAX, youbot_hold_need


@dataclass
class UnloadPath:
    """The youBot's joint positions for one unload, all at one tool tilt."""
    hover: np.ndarray             # over the material on the plate
    contact: np.ndarray           # the fingers round it
    lift: List[np.ndarray]        # up off the plate, straight, to clear of its neighbours
    over: np.ndarray              # 5 cm above its drop
    drop: np.ndarray              # where it is let go
    place: int = -1               # the destination's slot it is set down on (not the pool)
    pose: Optional[Pose2D] = None  # where the base stands for it


# A youBot unload whose drop is reached at another tool tilt than its grip rises this much more
# before the wrist turns [m].
TILT_CHANGE_RISE_M = 0.06
# A heavy material's unload slides the base along its stand's line only this far or further
# (nearer, it is unloaded from where the base stands) [m].
SLIDE_MIN_M = 0.03
# The speeds at its top tried for a lift that goes on to the drop, as fractions of its own top
# speed: the one whose whole motion ends soonest within the joints' limits is kept.
UNLOAD_LIFT_END_SPEEDS = (0.0, 0.25, 0.5, 0.75, 1.0)


_S = TransportState
# The states each state may be followed by (`enter` checks it; pipeline_diagram draws it).
TRANSPORT_TRANSITIONS = transition_table({
    _S.WAIT_LOAD: (_S.DRIVE, _S.DONE),
    # On to the next stand (or the slide along a stand's line); the arm down onto the first
    # material there as the base drives; home: wait for the next load, or fold.
    _S.DRIVE: (_S.DRIVE, _S.GRASP, _S.WAIT_LOAD, _S.FOLD),
    # A missed grasp tried again; off the plate; the unload given up, on to the next (at
    # another stand, or home).
    _S.GRASP: (_S.GRASP, _S.CARRY, _S.DRIVE),
    _S.CARRY: (_S.CARRY, _S.RELEASE, _S.GRASP, _S.DRIVE),
    _S.RELEASE: (_S.GRASP, _S.DRIVE),
    _S.FOLD: (_S.DONE,),
    _S.DONE: (),
})


class Transport(Machine):
    """The youBot: waits for its load, drives along Bezier paths with a PD follower, unloads
    one material at a time (into the pool over its wall, onto another destination's free
    slot), drives home."""

    state: TransportState

    name = 'transport'
    TRANSITIONS = TRANSPORT_TRANSITIONS

    def __init__(self, arm: YoubotArm, book: MaterialBook, log: EventLog, layout: CellLayout,
                 settings: Settings, ports: Ports, loader_done: Callable[[], bool],
                 zu12_clear: Callable[[float], bool]) -> None:
        """``loader_done`` and ``zu12_clear`` are the questions the youBot asks of the Zu 12:
        whether it has nothing more to load, and whether its cup is clear of the plate at a
        time (the base may move)."""
        super().__init__(arm, log, settings, TransportState.WAIT_LOAD)
        self.arm: YoubotArm = arm
        self.book, self.layout, self.ports = book, layout, ports
        self.loader_done, self.zu12_clear = loader_done, zu12_clear
        self.queue: List[Material] = []              # still to unload, the current one first
        self._follower: Optional[PathFollower] = None   # while the base drives
        self._followed = False                           # the port runs the follower
        self._drive_goal = ''
        self._target: Optional[Pose2D] = None          # the drive's end pose
        self._carry: Optional[UnloadPath] = None     # the unload's joint positions
        self._armed = False
        self._drive_deadline = math.inf
        # The arm holds a material up, over the plate, until the base stands at its stand.
        self._drop_pending = False
        self.trips = 0                                  # loads it has set off with
        S = TransportState
        self.handlers = {S.WAIT_LOAD: self._wait_load, S.DRIVE: self._drive,
                         S.GRASP: self._grasp, S.CARRY: self._carry_to_drop,
                         S.RELEASE: self._release, S.FOLD: self._fold,
                         S.DONE: lambda obs: None}

    @property
    def current(self) -> Optional[Material]:
        return self.queue[0] if self.queue else None

    @property
    def driving(self) -> bool:
        return self._follower is not None

    def tick(self, obs: Observation) -> None:
        if self._follower is not None:
            self._steer(obs)
        super().tick(obs)

    def _steer(self, obs: Observation) -> None:
        """The base along its path, with its follower, until it is there or out of time."""
        follower = known(self._follower, 'the path follower')
        status = follower.update(obs.now, obs.youbot_pose, obs.youbot_velocity[:2],
                                 obs.youbot_velocity[2])
        if not self._followed:
            self.ports.drive(*status.command)
        if not (status.finished or obs.now > self._drive_deadline):
            return
        self._follower = None
        self.ports.follow(None)
        self.ports.drive(0.0, 0.0, 0.0)
        if not status.finished:
            self.log.event(obs.now, EventKind.DRIVE_STALLED, self.arm.name, detail=(
                f'{status.position_error * 1000:.0f} mm from {self._drive_goal}'))
        self.log.event(obs.now, EventKind.ARRIVED, self.arm.name, detail=self._drive_goal)

    @property
    def loading(self) -> bool:
        """Whether the youBot waits at home for its load (the Zu 12 may load its plate)."""
        return self.state is TransportState.WAIT_LOAD and not self.driving

    def _load_complete(self, on_plate: Sequence[Material]) -> bool:
        """Whether this trip's load is on the plate: every carried material the batch brings
        (or the Zu 12 is done); or the plate has no room for the next one waiting on the belt
        (it goes on the next trip). It waits while a carried material on its way could still
        have a place."""
        if self.loader_done():
            return True
        if any(m.status == MaterialStatus.PICKING and self.layout.carried(m.color)
               for m in self.book.materials.values()):
            return False
        waiting = [m for m in self.book.materials.values()
                   if m.status == MaterialStatus.SEEN and self.layout.carried(m.color)]
        if any(self.book.plate_slots(m) for m in waiting):
            return False
        if waiting:
            return bool(on_plate)           # (full for what waits: off to make room)
        coming = [c for c in self.layout.manifest
                  if self.layout.carried(c) and self.book.to_come(c)]
        return bool(on_plate) and not any(
            self.layout.free_slots(c, self.book.plate_taken(), self.book.to_come_counts())
            for c in coming)

    def _wait_load(self, obs: Observation) -> None:
        on_plate = self.book.with_status(MaterialStatus.ON_PLATE)
        if not self._load_complete(on_plate) or not self.zu12_clear(obs.now):
            return      # (nor while the Zu 12's cup is over the plate, or swinging home from it)
        order = [st.name for st in self.layout.stands]
        self.queue = sorted(on_plate, key=lambda m: (
            order.index(self._stand_for(m)), self.layout.destination(m.color) != POOL, m.slot))
        if not self.queue:
            self.enter(TransportState.DONE, obs.now, math.inf)
            return
        self.trips += 1
        self.log.event(obs.now, EventKind.DEPARTING, self.arm.name,
                       detail=f'{len(self.queue)} materials, trip {self.trips}')
        # The arm rises to its carry pose while the base drives: folded, it reaches down in
        # front of the base, and its fingers would scrape the floor as the base pitches.
        self._drive_to(obs, self._stand_for(self.queue[0]))

    def _stand_for(self, m: Material) -> str:
        return self.layout.stand_for(m.color, m.slot).name

    def _drive_to(self, obs: Observation, goal: str) -> None:
        """Home, or to a stand: where it stands for the first material it unloads there (the
        stand's pose, or slid along its line for a heavy one, _unload_path), the arm readied
        for that material on the way."""
        lay = self.layout
        plan = None
        if goal == 'home':
            target, via = lay.youbot_home, lay.via_back
        else:
            target = lay.stand(goal).pose
            if self.queue:
                plan = self._unload_path(self.queue[0], target, YOUBOT_CARRY_Q, high=True,
                                         slide=True)
                target = plan.pose if plan is not None and plan.pose is not None else target
            via = (lay.way_out(goal) if self._drive_goal in ('', 'home')
                   else lay.via_turn if self._drive_goal != goal else ())
        self._follow(obs, target, via, goal)
        self.enter(TransportState.DRIVE, obs.now, self._drive_deadline - obs.now)
        if goal != 'home' and self.queue:
            self._ready_arm(obs, plan)

    def _follow(self, obs: Observation, target: Pose2D, via: Sequence[Any], goal: str) -> None:
        """The base off along a path from where it is through ``via`` to ``target`` (at stand
        or home ``goal``)."""
        x, y, yaw = (float(v) for v in obs.youbot_pose)
        path = BezierPath(key_poses_between((x, y, yaw), target, via))
        # Mecanum: the heading turns on its own profile in time while the base travels the
        # path, both over the same time (a short path with a large turn takes the turn's).
        self._follower = PathFollower(
            path, obs.now, self.s.drive_speed, self.s.drive_accel,
            PDGains(max_speed=self.s.base_max_speed, max_turn=self.s.base_max_turn),
            turn=TurnLimits(self.s.drive_turn, self.s.drive_turn_accel))
        self._followed = self.ports.follow(self._follower)
        self._drive_goal, self._target = goal, target
        self.log.event(obs.now, EventKind.DRIVING, self.arm.name,
                       detail=f'to {goal}, {path.length:.2f} m')
        self._drive_deadline = (obs.now + self._follower.profile.duration
                                + self.s.drive_margin)

    def _drive(self, obs: Observation) -> None:
        if self._drive_goal == 'home':
            if self.driving:
                return
            # Back to its start pose only at home, from the carry pose (a folded arm reaches
            # down in front of the base, and its fingers would catch the floor as the base
            # pitches). The cell's youBot starts in the carry pose: nothing is left to do.
            if not self.motion_over(obs, 'carry pose'):
                return
            if self.book.carried_to_come() and not self.loader_done():
                # More to carry: it waits here, the arm in its carry pose, for the next load.
                self.log.event(obs.now, EventKind.WAITING_FOR_LOAD, self.arm.name,
                               detail=f'{self.book.carried_to_come()} carried materials to come')
                return self.enter(TransportState.WAIT_LOAD, obs.now, math.inf)
            self.arm.go_home(obs)
            return self.enter(TransportState.FOLD, obs.now, self.arm.motion.end
                              - obs.now + self.s.settle_margin)
        # Here only when the arm could not be sent down onto the first material it unloads
        # here (_ready_arm): from the carry pose, the unload is planned (or its failure told).
        if self.queue and not self.motion_over(obs, 'carry pose'):
            return
        if self.queue or not self.driving:
            self._next_unload(obs)

    def _next_unload(self, obs: Observation) -> None:
        if not self.queue:
            # Home: the arm rises from the drop (its fingers 4 cm over the pool's wall) to the
            # upright carry pose as the base sets off (slowly: in the first 0.3 s it moves 3 cm,
            # the fingers rise further).
            self.arm.send(self.arm.plan(self.arm.q(obs), [Waypoint(YOUBOT_CARRY_Q.copy())]))
            return self._drive_to(obs, 'home')
        m = self.queue[0]
        if self._stand_for(m) != self._drive_goal:
            return self._drive_to(obs, self._stand_for(m))
        self._plan_unload(obs, m)

    def _ready_arm(self, obs: Observation, path: Optional['UnloadPath']) -> None:
        """While the base drives to a stand: the arm up through the carry pose (folded, it
        reaches down in front of the base, and its fingers would scrape the floor as the base
        pitches), over the first material it unloads there, and on down onto it without
        stopping over it: the grasp starts as the arm arrives, the base still on its way or
        not. Between the stands the arm swings joint 1 round 4.1 rad, and the first grasp there
        waited for it: a stop 12 cm over the material, and the descent from there, added 0.7 s
        to that wait."""
        m = self.queue[0]
        if path is None:
            # Up to the carry pose; the unload is planned (and its failure told) from there.
            self.arm.send(self.arm.plan(self.arm.q(obs), [Waypoint(YOUBOT_CARRY_Q.copy())]))
            return
        self._approach(obs, m, path, [Waypoint(YOUBOT_CARRY_Q.copy(), stop=False)])

    def _unload_path(self, m: Material, pose: Pose2D, seed: np.ndarray,
                     high: bool = False, slide: bool = False) -> Optional['UnloadPath']:
        """Joint positions over the material on the plate (5 cm over it with ``high``, else 3), on
        it, up its straight lift clear of its neighbours, above its drop and at its drop, for
        the base standing at ``pose``. The fingers come down from 3 cm over its top face (the
        neighbours' tops are level with it). The material rises 6 cm, over their 5 cm, before it
        swings out, through a point every centimetre at the same tool tilt: between two points
        6 cm apart the joints' straight line swings what is held 2 cm sideways and tilts it 8
        degrees, into a neighbour 1 cm away. With ``slide``, where the arm holds the material
        at none of its drops from ``pose``, the base may stand elsewhere along its stand's
        line: abeam the drop nearest there that it holds it at (UnloadPath.pose)."""
        size, t = m.size, self.s.timing
        mass = self.layout.rule(m.color).mass
        stand = self._stand_for(m)
        region = self.layout.region_of(m.color)
        # The swing over to a set-down comes in over what is there already (5 cm over the drop
        # is too little for 55 mm materials): it is as high over the drop as that asks.
        clear = 0.0 if region.drop else self.book.set_down_rise(region.name)
        if not region.drop:
            # Its destination's free slots, the first the arm reaches from here.
            up = np.array([0.0, 0.0, size + t.place_gap + YOUBOT_GRASP_STANDOFF_M])
            candidates = [(k, region.slots[k] + up) for k in self.book.free_places(region.name, m)]
        else:
            # The stand's first unused drop; if the arm cannot reach it from this slot as the
            # base stands (a far slot, a base a centimetre off), the others in turn. A drop
            # spot is used once: a cube dropped onto another can tumble back over the wall.
            drops = self.layout.stand(stand).drops
            used = self.book.dropped(stand)
            candidates = [(k, d) for k, d in enumerate(drops) if k not in used]
        # First a way whose every pose the arm holds with the material at rest (its load
        # within youbot_holds); only if there is none, the first it reaches (a heavy material
        # held out over a far drop sags the arm, but is still delivered).
        for load in (mass, 0.0) if mass > 0.0 else (0.0,):
            path = self._unload_way(m, pose, seed, high, load, candidates, clear)
            if path is None and slide and load > 0.0:
                path = self._slid_way(m, pose, seed, high, load, candidates, clear)
            if path is not None:
                return path
        return None

    def _slid_way(self, m: Material, pose: Pose2D, seed: np.ndarray, high: bool, load: float,
                  candidates: Sequence[Tuple[int, np.ndarray]], clear: float
                  ) -> Optional['UnloadPath']:
        """_unload_path's way to a candidate from the base slid along its stand's line abeam
        of it (UnloadStand.abeam; at least SLIDE_MIN_M from ``pose``), in the candidates' order
        (the pool's spots nearest its wall first, a destination's slots nearest the stand): a
        heavy material's far drops are beyond what the arm holds (the shoulder sags, or the
        arm stalls). (Taken by the shortest slide, a 0.08 kg orange went to a spot 21 cm in from
        the wall, 7 cm from one that had landed 5 cm off its own, and landed on it.)"""
        stand = self.layout.stand(self._stand_for(m))
        for place, point in candidates:
            at = stand.abeam(point)
            if math.hypot(at[0] - pose[0], at[1] - pose[1]) < SLIDE_MIN_M:
                continue
            path = self._unload_way(m, at, seed, high, load, [(place, point)], clear)
            if path is not None:
                return path
        return None

    def _unload_way(self, m: Material, pose: Pose2D, seed: np.ndarray, high: bool,
                    load: float, candidates: Sequence[Tuple[int, np.ndarray]], clear: float
                    ) -> Optional['UnloadPath']:
        """_unload_path's way to the first of ``candidates`` (place, world point) the arm
        reaches, holding ``load`` kg at rest from the grip on."""
        region = self.layout.region_of(m.color)
        contact, hover, lift = grip_points(self.layout.plate_slots[m.slot], m.size,
                                           m.unload_attempts, high, self._tallest_other(m))
        for place, drop_world in candidates:
            drop = world_to_base(pose, drop_world)
            drop[2] -= self.layout.youbot_base_z
            # Over the drop, at least as high as the lift's top: a swing there keeps what is
            # held over the plate's other materials where a joint motion from the lift's top
            # straight down to a pool drop (lower than the plate) would swing it into the next
            # one. Taken only when that is so (_lift).
            over = drop.copy()
            over[2] = max(drop[2] + 0.05, lift[-1][2], drop[2] + clear)
            # (Held from the contact on: the arm must hold it still all the way to its drop.)
            path = self.arm.solve_tilted([hover, contact, *lift, over, drop],
                                         np.array(seed, float), load, held_from=1)
            if path is None and region.drop:
                # A drop spot further in is reached leaning another way: the material, let go
                # over the pool, need not stay level (one it is set down must). It rises
                # TILT_CHANGE_RISE_M more first, still level, so that what it holds clears the
                # others on the plate as the wrist turns.
                rise = np.array(lift[-1], float) + np.array([0.0, 0.0, TILT_CHANGE_RISE_M])
                grip = self.arm.solve_tilted([hover, contact, *lift, rise], np.array(seed, float),
                                             load, held_from=1)
                above = np.array(over, float)
                above[2] = max(over[2], rise[2])
                out = (self.arm.solve_tilted([above, drop], grip[-1], load) if grip is not None
                       else None)
                path = grip + out if grip is not None and out is not None else None
            if path is not None:
                return UnloadPath(path[0], path[1], path[2:-2], path[-2], path[-1], place,
                                  pose)
        return None

    def _lift(self, obs: Observation, m: Material, then: Sequence[Waypoint] = (),
              detour: Sequence[Waypoint] = ()) -> Points:
        """The motion from the grip: the straight lift off the plate, timed along the line (a
        joint motion between its ends would swing the material into its neighbours), at rest
        at its top, or going on from there through ``then`` (or ``detour`` where ``then``
        would not keep ``m`` clear of the plate's other materials): at the speed, of those
        tried, that ends soonest and keeps the joints within their limits."""
        limits = self.arm.limits
        others, offset = self._others(m), self._held_offset(obs, m)
        carry = known(self._carry, 'the unload path')
        for way in ((then, detour) if detour else (then,)):
            best = None
            for speed in (UNLOAD_LIFT_END_SPEEDS if way else (0.0,)):
                lift = timed_path([self.arm.q(obs), *carry.lift], limits,
                                  self.arm.clock.now + self.s.plan_latency, end_speed=speed,
                                  min_time=self.s.timing.lift)
                try:
                    points = self.arm.plan(self.arm.q(obs), [*lift, *way])
                except PlanError:
                    continue
                within = all(np.all(np.abs(v) <= limits.velocity) for _, _, v, _ in points)
                if (within and (best is None or points[-1][0] < best[-1][0])
                        and clear_of_the_plate(points, others, m.size, offset)):
                    best = points
            if best is not None:
                return best
        raise PlanError('no motion off the plate within the joint limits and clear of the '
                        'other materials')

    def _tallest_other(self, m: Material) -> float:
        """The tallest material on the plate but ``m`` (0: none)."""
        return max((o.size for o in self.book.materials.values()
                    if o.on_the_plate and o is not m), default=0.0)

    def _held_offset(self, obs: Observation, m: Material) -> np.ndarray:
        """Where ``m``, gripped over its plate slot, is from the tool (held_offset)."""
        return held_offset(self.arm.q(obs), self.layout.plate_slots[m.slot])

    def _others(self, m: Material) -> List[Tuple[float, float, float]]:
        """The materials on the plate but ``m``: their slots (x, y) and sizes."""
        return [(*self.layout.plate_slots[o.slot], o.size)
                for o in self.book.materials.values()
                if o.on_the_plate and o.slot >= 0 and o.id != m.id]

    def _stand_pose(self, obs: Observation) -> Pose2D:
        """Where the base stands for its unloads: its drive's end while it is on its way."""
        if self.driving:
            return known(self._target, 'the drive\'s end')
        return obs.youbot_pose

    def _plan_unload(self, obs: Observation, m: Material) -> None:
        """Down onto the material on the plate; the gripper closes once the arm is there.
        Standing, the base slides along its stand's line first where a heavy material is held
        out to its drop only from elsewhere on it (the arm on its way down meanwhile)."""
        now = obs.now
        here = self._stand_pose(obs)
        plan = self._unload_path(m, here, self.arm.q(obs), slide=not self.driving)
        if plan is None:
            self.queue.pop(0)
            self.book.give_up(now, m, EventKind.GRASP_FAILED, 'unload: no IK solution',
                              self.arm.name)
            return self._next_unload(obs)
        if plan.pose is not None and plan.pose is not here:
            self._follow(obs, plan.pose, (), self._drive_goal)
        self._approach(obs, m, plan)

    def _approach(self, obs: Observation, m: Material, plan: 'UnloadPath',
                  through: Sequence[Waypoint] = ()) -> None:
        """Down onto ``m`` on the plate through ``through`` and its hover; the gripper closes
        once the arm is there (GRASP)."""
        t = self.s.timing
        self._carry, self._armed = plan, False
        # (The place kept for it: the pool's drops are the stand's.)
        self.book.unload_attempt(m, plan.place)
        self.log.count_grasp(self.arm.name)
        self.move(TransportState.GRASP, obs, self.arm.plan(self.arm.q(obs), [
            *through, Waypoint(plan.hover, stop=False),
            Waypoint(plan.contact, hold=SETTLE_S, min_time=t.descend)]))

    def _grasp(self, obs: Observation) -> None:
        m, now = self.queue[0], obs.now
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if not arrived:
            return self._unload_failed(obs, m, EventKind.GRASP_FAILED,
                                       'unload: the arm did not reach the material')
        if not self._armed:
            # Closed only now: its 20 mm reach would take a neighbour on the way down.
            self.ports.grip(self.arm.name, True)
            self._armed = True
            return
        if not self.arm.armed(obs):
            if self.late(now):
                return self._unload_failed(obs, m, EventKind.GRASP_FAILED,
                                           'unload: the gripper does not report closing')
            return                      # (the grip state from before the gripper closed)
        if not self.arm.holding(obs):
            self.ports.grip(self.arm.name, False)
            self.log.event(now, EventKind.GRASP_MISSED, self.arm.name, m,
                           f'attempt {m.unload_attempts}')
            if m.unload_attempts <= self.s.max_retries:
                return self._plan_unload(obs, m)
            return self._unload_failed(obs, m, EventKind.GRASP_FAILED, f'unload: not held after '
                                       f'{m.unload_attempts} attempts')
        self.log.count_grasp(self.arm.name, success=True)
        self.log.event(now, EventKind.UNLOAD_GRASPED, self.arm.name, m,
                       f'attempt {m.unload_attempts}')
        if self.driving:
            # Up clear of its neighbours, and held there until the base stands.
            self._drop_pending = True
            try:
                return self.move(TransportState.CARRY, obs, self._lift(obs, m))
            except PlanError as exc:
                return self._unload_failed(obs, m, EventKind.FAILED, f'unload: {exc}')
        self._carry_out(obs, m, known(self._carry, 'the unload path').over,
                            known(self._carry, 'the unload path').drop, lift=True)

    def _carry_out(self, obs: Observation, m: Material, over: np.ndarray, drop: np.ndarray,
                   lift: bool = False) -> None:
        """Over to the material's drop (first up off the plate with ``lift``)."""
        t = self.s.timing
        self._drop_pending = False
        if not self.layout.region_of(m.color).drop:
            # Set down on its slot gently, from above, and still before letting go.
            carry = [Waypoint(over, stop=False),
                     Waypoint(drop, hold=SETTLE_S, min_time=t.place_descend)]
        else:
            # Let go over the pool, 14 cm up (4 cm over its walls): straight there, or over it
            # first where the straight swing would not clear the plate's other materials.
            carry = [Waypoint(drop)]
        detour = [Waypoint(over, stop=False), Waypoint(drop)]
        try:
            if lift:
                try:
                    points = self._lift(obs, m, carry, detour)
                except PlanError:
                    # No one motion off the plate and on over the drop (one reached at another
                    # tilt: the wrist turns on the way): up clear of the others and still
                    # first, and over from there (_carry_to_drop).
                    self._drop_pending = True
                    return self.move(TransportState.CARRY, obs, self._lift(obs, m))
            else:       # (from the lift's top, where it waited for the base to stand)
                points = self.arm.plan(self.arm.q(obs), carry)
                if not clear_of_the_plate(points, self._others(m), m.size,
                                          self._held_offset(obs, m)):
                    points = self.arm.plan(self.arm.q(obs), detour)
        except PlanError as exc:
            return self._unload_failed(obs, m, EventKind.FAILED, f'unload: {exc}')
        self.move(TransportState.CARRY, obs, points)

    def _unload_failed(self, obs: Observation, m: Material, kind: EventKind, why: str) -> None:
        self._drop_pending = False
        self.ports.grip(self.arm.name, False)
        self.book.left_on_plate(m)
        self.queue.pop(0)
        self.book.give_up(obs.now, m, kind, why, self.arm.name)
        self._next_unload(obs)

    def _carry_to_drop(self, obs: Observation) -> None:
        m, now = self.queue[0], obs.now
        if not self.arm.holding(obs):
            return self._unload_failed(obs, m, EventKind.FAILED, 'unload: dropped on the way')
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if self._drop_pending:
            if self.driving:
                return              # (held up over the plate until the base stands)
            if not arrived:
                self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                               'the lift off the plate not completed')
            # Over to its drop as the base stands now (the drive ends a little off its goal).
            path = (self._unload_path(m, obs.youbot_pose, self.arm.q(obs))
                    or known(self._carry, 'the unload path'))
            self._carry = path
            self.book.keep_place(m, path.place)
            return self._carry_out(obs, m, path.over, path.drop)
        if not arrived:
            held = self._held_beyond(obs, m)
            self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                           'unload motion not completed' + held)
            short = self._short_of_drop(obs)
            if short > DROP_REACH_TOLERANCE_M:
                # Let go where it is, and not told delivered: a 0.44 kg blue whose unload
                # stalled 2 cm over its plate slot was reported set down on the platform.
                return self._unload_failed(obs, m, EventKind.FAILED, f'unload: the arm stalled '
                                           f'{short:.2f} m short of the drop' + held)
        self.ports.grip(self.arm.name, False)
        self.book.delivered(m, self._drive_goal)
        where = self.layout.destination(m.color)
        if self.layout.region_of(m.color).drop:
            where += f' drop {m.place} from {self._drive_goal}'
        else:
            where += f' slot {m.place}'
        self.log.event(now, EventKind.DELIVERED, self.arm.name, m, where)
        # The arm stays still while the material falls free of the fingers.
        self.enter(TransportState.RELEASE, now, RELEASE_HOLD_S)

    def _held_beyond(self, obs: Observation, m: Material) -> str:
        """Where the arm, as it stands, holds ``m`` beyond what it may (YOUBOT_LOAD_MAX of a
        joint's effort, at rest): which joint, and the torque it takes ('' where it does not):
        an arm that cannot hold its load sags, and says why."""
        mass = self.layout.rule(m.color).mass
        joint, torque, effort = youbot_hold_need(self.arm.q(obs), mass)
        if torque <= YOUBOT_LOAD_MAX * effort:
            return ''
        return (f'; holding {mass:g} kg there, {joint} needs {torque:.2f} N m at rest '
                f'(its motor: {effort:g} N m)')

    def _short_of_drop(self, obs: Observation) -> float:
        """How far the gripper is from the unload's drop, across [m] (the arm's forward
        kinematics, where it is and where its motion ends)."""
        return short_of(self.arm.q(obs), known(self._carry, 'the unload path').drop)

    def _release(self, obs: Observation) -> None:
        if not self.late(obs.now):
            return
        dq = self.arm.dq(obs)
        still = dq is None or float(np.max(np.abs(dq))) <= self.s.rest_speed
        if still or obs.now > self.deadline + SPRING_BACK_WAIT_S:
            self.queue.pop(0)
            self._next_unload(obs)

    def _fold(self, obs: Observation) -> None:
        if self.motion_over(obs, 'home pose'):
            self.enter(TransportState.DONE, obs.now, math.inf)
