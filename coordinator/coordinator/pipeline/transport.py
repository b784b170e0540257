"""The transport: the youBot carries its load to the pool and unloads it."""
from __future__ import annotations

import math
from typing import Callable, List, Optional, Sequence

import numpy as np

from cell_layout.fleet_routes import way_between, way_off, way_to_park
from cell_layout.layout import POOL, YOUBOT_CARRY_Q, CellLayout
from cell_layout.unload_geometry import (
    DROP_REACH_TOLERANCE_M,
    UnloadPath,
    clear_of_the_plate,
    short_of,
    touched_edge,
)
from controllers.path_follower import PathFollower
from controllers.time_optimal import (
    PlanError,
    Waypoint,
)
from coordinator.pipeline.machine import Machine, transition_table
from coordinator.pipeline.materials import MaterialBook
from coordinator.pipeline.model import (
    RELEASE_HOLD_S,
    SETTLE_S,
    SPRING_BACK_WAIT_S,
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
from coordinator.pipeline.robots import BaseDrive, YoubotArm
from coordinator.pipeline.room import Room
from coordinator.pipeline.traffic import LOADING, Traffic, stands_place
from coordinator.pipeline.unload_planner import UnloadPlanner
from trial_record.events import EventKind

_S = TransportState
# The states each state may be followed by (`enter` checks it; pipeline_diagram draws it).
TRANSPORT_TRANSITIONS = transition_table({
    _S.WAIT_LOAD: (_S.DRIVE, _S.DONE),
    # On to the next stand (or the slide along a stand's line); the arm down onto the first
    # material there as the base drives; home: wait for the next load, or fold; at its park:
    # wait for the loading pose, or fold.
    _S.DRIVE: (_S.DRIVE, _S.GRASP, _S.WAIT_LOAD, _S.WAIT_BAY, _S.FOLD),
    # A missed grasp tried again; off the plate; the unload given up, on to the next (at
    # another stand, or home; or waiting to drive off the pool).
    _S.GRASP: (_S.GRASP, _S.CARRY, _S.DRIVE, _S.LEAVE),
    _S.CARRY: (_S.CARRY, _S.RELEASE, _S.GRASP, _S.DRIVE, _S.LEAVE),
    _S.RELEASE: (_S.GRASP, _S.DRIVE, _S.LEAVE),
    _S.LEAVE: (_S.DRIVE,),
    _S.WAIT_BAY: (_S.DRIVE, _S.FOLD),
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
                 loader_clear: Callable[[float], bool], base: BaseDrive,
                 traffic: Traffic) -> None:
        """``loader_done`` and ``loader_clear`` are the questions the youBot asks of the loader:
        whether it has nothing more to load, and whether its cup is clear of the plate at a
        time (the base may move). ``traffic``: the fleet's rules (a fleet of one: it starts
        at the loading pose, and nothing holds it back); ``base`` drives its base."""
        super().__init__(arm, log, settings, TransportState.WAIT_BAY if layout.fleet
                         else TransportState.WAIT_LOAD)
        self.arm: YoubotArm = arm
        self.book, self.layout, self.ports = book, layout, ports
        self.room = Room(book, layout, settings)          # (a view: questions on the book)
        self.loader_done, self.loader_clear = loader_done, loader_clear
        self.queue: List[Material] = []              # still to unload, the current one first
        self.base, self.traffic = base, traffic
        self.robot = arm.name
        self.pool = stands_place(layout.side_of(self.robot))   # (where it unloads: Traffic)
        if layout.fleet:
            self.name = arm.name                # (its states' lane: one per youBot)
        self.planner = UnloadPlanner(arm, book, layout, settings)
        self._carry: Optional[UnloadPath] = None     # the unload's joint positions
        self._armed = False
        # The arm holds a material up, over the plate, until the base stands at its stand.
        self._drop_pending = False
        self.trips = 0                                  # loads it has set off with
        self.carried = 0                                # materials it has set off with
        S = TransportState
        self.handlers = {S.WAIT_LOAD: self._wait_load, S.DRIVE: self._drive,
                         S.GRASP: self._grasp, S.CARRY: self._carry_to_drop,
                         S.RELEASE: self._release, S.FOLD: self._fold,
                         S.LEAVE: self._off_the_pool, S.WAIT_BAY: self._wait_bay,
                         S.DONE: lambda obs: None}

    @property
    def current(self) -> Optional[Material]:
        return self.queue[0] if self.queue else None

    def tick(self, obs: Observation) -> None:
        if self.base.driving:
            self.base.steer(obs)
        super().tick(obs)

    @property
    def loading(self) -> bool:
        """Whether the youBot waits at home for its load (the loader may load its plate)."""
        return self.state is TransportState.WAIT_LOAD and not self.base.driving

    def _wait_load(self, obs: Observation) -> None:
        on_plate = [m for m in self.book.with_status(MaterialStatus.ON_PLATE)
                    if m.plate == self.robot]
        # (Nothing on its plate nor on its way there, and nothing to come has a place on it:
        # its side of the pool is full.)
        idle = not (on_plate or self.room.can_take(self.robot) or any(
            m.plate == self.robot for m in self.book.with_status(MaterialStatus.PICKING)))
        if (not (self.loader_done() or self.room.load_complete(self.robot, bool(on_plate))
                 or idle)
                or not self.loader_clear(obs.now)):
            return      # (nor while the loader's cup is over the plate, or swinging home from it)
        order = [st.name for st in self.layout.stands]
        queue = sorted(on_plate, key=lambda m: (
            order.index(self.planner.stand_for(m)), self.layout.destination(m.color) != POOL,
            m.slot))
        if not queue and not self.loader_done() and self.layout.fleet:
            # Nothing for it to come (its side of the pool full): off to its park, to fold.
            if self._drive_to(obs, 'park'):
                self.traffic.leave(self.robot, LOADING)
            return
        if not queue:
            self.traffic.leave(self.robot, LOADING)
            self.enter(TransportState.DONE, obs.now, math.inf)
            return
        if not self.traffic.ask(self.robot, self.pool):
            return                                  # (another youBot unloads there)
        self.queue = queue

        def departing() -> None:
            self.trips += 1
            self.carried += len(self.queue)
            self.log.event(obs.now, EventKind.DEPARTING, self.arm.name,
                           detail=f'{len(self.queue)} materials, trip {self.trips}')
        # The arm rises to its carry pose while the base drives: folded, it reaches down in
        # front of the base, and its fingers would scrape the floor as the base pitches.
        if self._drive_to(obs, self.planner.stand_for(self.queue[0]), departing):
            self.traffic.leave(self.robot, LOADING)

    def _wait_bay(self, obs: Observation) -> None:
        """At its park: to the loading pose once it is its turn there, or folded once nothing
        more is to come."""
        if (not self.room.carried_to_come() or self.loader_done()
                or not self.room.can_take(self.robot)):
            self.traffic.leave(self.robot, LOADING)
            self.arm.go_home(obs)
            return self.enter(TransportState.FOLD, obs.now, self.arm.motion.end
                              - obs.now + self.s.settle_margin)
        if self.traffic.ask(self.robot, LOADING):
            # (Its arm to the carry pose on the way, as on every drive to the loading pose.)
            self._drive_to(obs, 'home', lambda: self.arm.send(self.arm.plan(
                self.arm.q(obs), [Waypoint(YOUBOT_CARRY_Q.copy())])))

    def _off_the_pool(self, obs: Observation) -> None:
        """Unloaded: to the loading pose if it is free for this youBot and it has more to
        carry, else to its park; the pool is free once it sets off (LEAVE while the drive is
        held back). (A fleet's youBot done at the loading pose stood in the way of another
        coming back from the pool, for ever.)"""
        more = self.room.carried_to_come() and not self.loader_done() and self.room.can_take(
            self.robot)
        goal = ('home' if (more or not self.layout.fleet) and self.traffic.ask(self.robot, LOADING)
                else 'park')
        if self._drive_to(obs, goal):
            self.traffic.leave(self.robot, self.pool)
        elif self.state is not TransportState.LEAVE:
            self.enter(TransportState.LEAVE, obs.now, math.inf)

    def _drive_to(self, obs: Observation, goal: str,
                  departing: Callable[[], object] = lambda: None) -> bool:
        """Home (the loading pose), to its park, or to a stand: where it stands for the first
        material it unloads there (the stand's pose, or slid along its line for a heavy one,
        _unload_path), the arm readied for that material on the way. Whether it set off (the
        fleet's rule may hold it back: Traffic.clear); ``departing`` is told first."""
        lay = self.layout
        plan = None
        if goal == 'park':
            target = lay.park(self.robot)
            # (From the loading pose: its way there from its park, the other way round.)
            via = (way_to_park(lay, lay.stand(self.base.goal), target)
                   if any(st.name == self.base.goal for st in lay.stands) else ())
        elif goal == 'home':
            target = lay.youbot_home
            via = (() if self.base.goal in ('', 'park', 'home')
                   else way_off(lay, lay.stand(self.base.goal), target))
        else:
            target = lay.stand(goal).pose
            via = (lay.way_out(goal) if self.base.goal in ('', 'home')
                   else way_between(lay, lay.stand(goal)) if self.base.goal != goal else ())
            if lay.fleet and not self.traffic.clear(
                    self.robot, self.base.path_to(obs, target, via), obs):
                return False            # (held back: the unload is planned once it may go)
            departing()
            if self.queue:
                plan = self.planner.unload_path(self.queue[0], target, YOUBOT_CARRY_Q, high=True,
                                         slide=True)
                target = plan.pose if plan is not None and plan.pose is not None else target

        def clear(follower: PathFollower) -> bool:
            if goal not in ('home', 'park'):
                return True     # (cleared above: the slide along the stand's line is the pool's)
            if not self.traffic.clear(self.robot, follower, obs):
                return False
            departing()
            return True
        if not self.base.follow(obs, target, via, goal, clear):
            return False
        self.enter(TransportState.DRIVE, obs.now, self.base.deadline - obs.now)
        if goal not in ('home', 'park') and self.queue:
            self._ready_arm(obs, plan)
        return True

    def _drive(self, obs: Observation) -> None:
        if self.base.goal == 'park':
            if not self.base.driving and self.motion_over(obs, 'carry pose'):
                self.enter(TransportState.WAIT_BAY, obs.now, math.inf)
            return
        if self.base.goal == 'home':
            if self.base.driving:
                return
            # Back to its start pose only at home, from the carry pose (a folded arm reaches
            # down in front of the base, and its fingers would catch the floor as the base
            # pitches). The cell's youBot starts in the carry pose: nothing is left to do.
            if not self.motion_over(obs, 'carry pose'):
                return
            if self.room.carried_to_come() and not self.loader_done():
                # More to carry: it waits here, the arm in its carry pose, for the next load.
                self.log.event(obs.now, EventKind.WAITING_FOR_LOAD, self.arm.name,
                               detail=f'{self.room.carried_to_come()} carried materials to come')
                return self.enter(TransportState.WAIT_LOAD, obs.now, math.inf)
            self.arm.go_home(obs)
            return self.enter(TransportState.FOLD, obs.now, self.arm.motion.end
                              - obs.now + self.s.settle_margin)
        # Here only when the arm could not be sent down onto the first material it unloads
        # here (_ready_arm): from the carry pose, the unload is planned (or its failure told).
        if self.queue and not self.motion_over(obs, 'carry pose'):
            return
        if self.queue or not self.base.driving:
            self._next_unload(obs)

    def _next_unload(self, obs: Observation) -> None:
        if not self.queue:
            # Home: the arm rises from the drop (its fingers 4 cm over the pool's wall) to the
            # upright carry pose as the base sets off (slowly: in the first 0.3 s it moves 3 cm,
            # the fingers rise further).
            self.arm.send(self.arm.plan(self.arm.q(obs), [Waypoint(YOUBOT_CARRY_Q.copy())]))
            return self._off_the_pool(obs)
        m = self.queue[0]
        if self.planner.stand_for(m) != self.base.goal:
            # (Between the stands, the pool its own: nothing holds the drive back.)
            self._drive_to(obs, self.planner.stand_for(m))
            return
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

    def _plan_unload(self, obs: Observation, m: Material) -> None:
        """Down onto the material on the plate; the gripper closes once the arm is there.
        Standing, the base slides along its stand's line first where a heavy material is held
        out to its drop only from elsewhere on it (the arm on its way down meanwhile)."""
        now = obs.now
        here = self.base.stand_pose(obs)
        plan = self.planner.unload_path(m, here, self.arm.q(obs), slide=not self.base.driving)
        if plan is None:
            self.queue.pop(0)
            self.book.give_up(now, m, EventKind.GRASP_FAILED, 'unload: no IK solution',
                              self.arm.name)
            return self._next_unload(obs)
        if plan.pose is not None and plan.pose is not here:
            self.base.follow(obs, plan.pose, (), self.base.goal)
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
        if not arrived and not self._armed:
            # Stopped on its way down: on its top (it stands taller than loaded: its edge as
            # found is kept, and the fingers close there), or elsewhere: failed.
            edge = touched_edge(self.arm.q(obs), known(self._carry, 'the unload path').contact)
            if edge is None:
                return self._unload_failed(obs, m, EventKind.GRASP_FAILED,
                                           'unload: the arm did not reach the material')
            self.log.event(now, EventKind.REPLANNED, self.arm.name, m, f'the fingers met its top '
                           f'{1e3 * (edge - m.size):.1f} mm higher than loaded: gripped there')
            self.book.sized(m, edge)
            self.deadline = now + self.s.settle_margin      # (for the gripper to report)
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
        if self.base.driving:
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
                if not clear_of_the_plate(points, self.planner.others(m), m.size,
                                          self.planner.held_offset(obs, m)):
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
            if self.base.driving:
                return              # (held up over the plate until the base stands)
            if not arrived:
                self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                               'the lift off the plate not completed')
            # Over to its drop as the base stands now (the drive ends a little off its goal).
            carry = known(self._carry, 'the unload path')
            path = self.planner.unload_path(m, obs.bases[self.base.robot].pose, self.arm.q(obs),
                                            gripped=carry.grip_tilt) or carry
            self._carry = path
            self.book.keep_place(m, path.place)
            return self._carry_out(obs, m, path.over, path.drop)
        if not arrived:
            held = self.planner.held_beyond(obs, m)
            self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                           'unload motion not completed' + held)
            short = short_of(self.arm.q(obs), known(self._carry, 'the unload path').drop)
            if short > DROP_REACH_TOLERANCE_M:
                # Let go where it is, and not told delivered: a 0.44 kg blue whose unload
                # stalled 2 cm over its plate slot was reported set down on the platform.
                return self._unload_failed(obs, m, EventKind.FAILED, f'unload: the arm stalled '
                                           f'{short:.2f} m short of the drop' + held)
        self.ports.grip(self.arm.name, False)
        self.book.delivered(m, self.base.goal)
        where = self.layout.destination(m.color)
        if self.layout.region_of(m.color).drop:
            let_go = known(self._carry, 'the unload path').let_go
            where += f' drop {m.place} (let go {let_go}) from {self.base.goal}'
        else:
            where += f' slot {m.place}'
        self.log.event(now, EventKind.DELIVERED, self.arm.name, m, where)
        # The arm stays still while the material falls free of the fingers.
        self.enter(TransportState.RELEASE, now, RELEASE_HOLD_S)

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
            self.traffic.leave(self.robot, LOADING)
            self.enter(TransportState.DONE, obs.now, math.inf)

    def _lift(self, obs: Observation, m: Material, then: Sequence[Waypoint] = (),
              detour: Sequence[Waypoint] = ()) -> Points:
        """The motion off the plate along the unload's lift (UnloadPlanner.lift)."""
        return self.planner.lift(obs, m, known(self._carry, 'the unload path'), then, detour)
