"""The loader: the arm that picks materials off the running belt and sets them down (any arm:
its model is the layout's)."""
from __future__ import annotations

import functools
import math
from typing import (
    Callable,
    List,
    Optional,
    Sequence,
    Tuple,
)

import numpy as np

from cell_layout.layout import CellLayout
from controllers.pick_place import PickTiming
from controllers.time_optimal import (
    Waypoint,
    plan,
)
from coordinator.pipeline.machine import Machine, transition_table
from coordinator.pipeline.materials import BeltModel, MaterialBook
from coordinator.pipeline.model import (
    CALL_OFF_M,
    FOLLOW_TOLERANCE,
    MAX_REPLANS,
    PICK_LEAD_S,
    PLAN_MARGIN,
    QUEUE_LIFT_PAUSE_LEAD_S,
    REAIM_LEAD_S,
    LoaderState,
    Material,
    MaterialStatus,
    Observation,
    Ports,
    Settings,
    known,
)
from coordinator.pipeline.pick_planner import LEAVE, Ahead, PickPlan, PickPlanner
from coordinator.pipeline.record import EventLog
from coordinator.pipeline.robots import Arm, CupPlace
from coordinator.pipeline.room import Room
from trial_record.events import EventKind

_S = LoaderState
# The states each state may be followed by (the loader's only way between states; `enter`
# checks it, docs/pipeline.md draws it: pipeline_diagram).
LOADER_TRANSITIONS = transition_table({
    _S.START: (_S.WAIT,),
    # A pick; the rise from a place with nothing to pick yet; a pick given up before it began;
    # loading over.
    _S.WAIT: (_S.PICK, _S.RISE, _S.RETREAT, _S.HOME),
    # The pick planned again (a missed grasp, a late start); on to the place; a pick that
    # cannot be made in time (back to waiting); a failure.
    _S.PICK: (_S.PICK, _S.PLACE, _S.WAIT, _S.RETREAT),
    _S.PLACE: (_S.WAIT, _S.RETREAT),
    _S.RISE: (_S.WAIT,),
    _S.RETREAT: (_S.WAIT,),
    _S.HOME: (_S.DONE,),
    _S.DONE: (),
})


class Loader(Machine):
    """The loader: picks materials off the running belt (meeting each where it will be, and
    moving with it while the cup is on it); a class it places itself onto its destination once
    it has ridden to the end stop, the carried ones onto the youBot's plate."""

    state: LoaderState

    name = 'loader'
    TRANSITIONS = LOADER_TRANSITIONS

    def __init__(self, arm: Arm, book: MaterialBook, belt: BeltModel, log: EventLog,
                 layout: CellLayout, settings: Settings, ports: Ports,
                 loading: Callable[[], Optional[str]]) -> None:
        """``loading``: the question the loader asks of the youBots, which of them waits at
        the loading pose for its load (None: none)."""
        super().__init__(arm, log, settings, LoaderState.START)
        self.book, self.belt, self.layout, self.ports = book, belt, layout, ports
        self.room = Room(book, layout, settings)          # (a view: questions on the book)
        self.loading = loading
        self.lag = 0.0                    # the longest a pick's plan has taken (real time) [s]
        self.current: Optional[Material] = None     # the material being picked or placed
        self.cup = CupPlace(arm, layout, settings)
        self.planner = PickPlanner(arm, book, belt, self.cup, layout, settings, loading)
        self._leave = math.inf                      # when the cup lifts the material
        self._ahead: Optional[Ahead] = None         # the pick's motion goes on to the place
        self._pick_plan: Optional[PickPlan] = None  # the pick under way, as last planned
        self._replans = 0                           # pick plans the port started late
        self._arm_pending = False                   # the cup goes on once it is clear
        # When the belt pauses for a lift out of the end stop's queue (from, to) [s].
        self.belt_pause: Tuple[float, float] = (math.inf, -math.inf)
        S = LoaderState
        self.handlers = {S.WAIT: self._wait, S.PICK: self._pick, S.PLACE: self._place,
                         S.RISE: functools.partial(self._when_there, 'the rise from the place',
                                                   S.WAIT),
                         S.RETREAT: functools.partial(self._when_there, 'retreat', S.WAIT),
                         S.HOME: functools.partial(self._when_there, 'home', S.DONE),
                         S.DONE: lambda obs: None}

    def start(self, obs: Observation) -> None:
        """The first observation: loading begins."""
        self.enter(LoaderState.WAIT, obs.now, self.s.idle_timeout)

    def _wait(self, obs: Observation) -> None:
        now = obs.now
        waiting = self.book.with_status(MaterialStatus.SEEN)
        accounted = len(self.book.materials) - len(waiting)
        if accounted >= self.layout.total or (not waiting and self.late(now)):
            why = ('every material handled' if accounted >= self.layout.total else
                   f'nothing new for {self.s.idle_timeout:.0f} s')
            self.log.event(now, EventKind.LOADING_OVER, self.arm.name, detail=why)
            self.log.event(now, EventKind.RETURNING, self.arm.name)
            return self._move(LoaderState.HOME, obs, [Waypoint(self.arm.home.copy())])
        m = self._next(waiting)
        if m is not None and not (self.belt.running and self.belt.sensed.source == 'set point'):
            # (Not before the camera has told the belt's speed: its set point is not it.)
            self._plan_pick(obs, m)
        if self.state is LoaderState.WAIT and self.cup.at_release:
            # Nothing to pick yet: up from the place, to wait there.
            self._move(LoaderState.RISE, obs, [])

    def _move(self, state: LoaderState, obs: Observation, waypoints: List[Waypoint],
              start: Optional[float] = None) -> None:
        """Send a motion through ``waypoints`` (planned from rest where the arm is); from a
        place the cup has just let go at, it first stays still while the material falls free
        and rises straight up."""
        points = self.cup.plan(obs, waypoints, start)
        self.move(state, obs, points, start)
        self.cup.after_send()

    def clear_of_the_plate(self, now: float) -> bool:
        """Whether the cup is away from the youBot's plate: not placing there, nor rising from
        it, nor swinging home (over it)."""
        return (self.state not in (LoaderState.PLACE, LoaderState.RISE, LoaderState.HOME)
                and self.cup.clear(now))

    def loadable(self, m: Material) -> bool:
        """Whether the loader may put ``m`` onto the youBot's plate now: it waits at home, and
        has a slot for it."""
        robot = self.loading()
        return robot is not None and bool(self.room.plate_slots(m, robot))

    def _next(self, waiting: Sequence[Material]) -> Optional[Material]:
        """The next material to pick: the most downstream one bound for the youBot's plate (the
        youBot waits for them); one the loader places itself once the end stop holds it (it
        rides to the end)."""
        ride = self.layout.end_stop
        # (The youBot takes a load only while it waits at home, with room on its plate: the
        # others ride on, and queue at the end stop until it is back.)
        # (One whose picks on the move missed waits until it rests at the end stop.)
        waiting = [m for m in waiting if m.at_rest_from < 0 or self.belt.held(m)]
        carried = [m for m in waiting if self.layout.carried(m.color)]
        now_ = [m for m in carried if self.loadable(m)]
        now_ += [m for m in waiting if not self.layout.carried(m.color) and not ride]
        if not now_:
            now_ = [m for m in waiting if not self.layout.carried(m.color) and self.belt.held(m)]
        return max(now_, key=lambda m: m.position[0], default=None)

    def _plan_pick(self, obs: Observation, m: Material, spent: float = 0.0) -> None:
        """Meet the material where it will be: the earliest contact the arm can make from
        where it is, past the pick point. One motion: to the hover point, arriving there with
        the path's velocity at its time, then down onto the material and on it while the cup
        seals, moving with it, and up to the lift height, at rest (and on to its place,
        ``_onward``). The cup is switched on once the motion is sent (an armed cup seals when
        it touches its part).

        Real time: ``spent`` is how long earlier plans of this pick took since ``obs.now``
        (the port started them late, so they were replaced before they began)."""
        t = self.s.timing
        # A second attempt presses 4 mm further down.
        timing = PickTiming(**{**t.__dict__, 'contact_gap': t.contact_gap - 0.004 * m.attempts})
        # Real time: allow for the longest a pick's plan has taken (a motion the port starts
        # later would come too late to a moving material), after what this one has spent.
        lag = self.lag
        start = obs.now + self.s.plan_latency + lag + spent
        pick = PickPlan(m, timing, self.belt.track(m), start, max(
            start + timing.descend + PICK_LEAD_S, self.belt.reaches(m, self.s.pick_x)))
        if not math.isfinite(pick.contact):
            return self._leave_it(obs, m)   # it does not reach the pick point (belt off)
        why = self.planner.approach(obs, pick) or self.planner.meet(obs, pick)
        if why == LEAVE:
            return self._leave_it(obs, m)
        if why:
            return self._pick_failed(obs, m, why)
        self._ahead = self.planner.onward(obs, pick)
        self._send_pick(obs, pick, lag, spent)

    def _send_pick(self, obs: Observation, pick: 'PickPlan', lag: float, spent: float) -> None:
        """Send the pick; plan it again if the port starts it late; switch the cup on."""
        m, now = pick.m, obs.now
        self.current = m
        self.book.picking(m)
        self.move(LoaderState.PICK, obs, pick.points, start=pick.start)
        late = self.arm.motion.start - pick.start
        if late > 1e-9:
            # The port started it later than planned: it would miss the material. This plan
            # took as long as was allowed for it and then ``late``; plan again at once, allowing
            # for that much after this one (the new motion replaces it before it starts).
            took = lag + late
            self.lag = max(self.lag, PLAN_MARGIN * took)
            self.log.event(now, EventKind.REPLANNED, self.arm.name, m,
                           f'the pick would start {late:.2f} s late')
            if self._replans < MAX_REPLANS:
                self._replans += 1
                return self._plan_pick(obs, m, spent + took)
            # Still late: hold the arm where it is (replacing the late motion before it
            # starts) and plan afresh on the next observation.
            self._replans = 0
            hold = self.arm.q(obs).copy()
            self.arm.hold(hold)
            return self._leave_it(obs, m)
        self._replans = 0
        # The cup is switched on (an armed cup seals on what it touches) now, or from a place
        # once it has risen from there: switched on where it let go, it would take the same
        # material again.
        self._arm_pending = self.cup.at_release
        if not self._arm_pending:
            ok, why = self.ports.grip(self.arm.name, True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        self.cup.after_send()
        self._leave = pick.contact + pick.timing.dwell + late
        self.book.coming_down(m, pick.hover_at + late - REAIM_LEAD_S)
        self._pick_plan = pick if not late else None
        if self._ahead is not None:
            self._ahead.lift_end += late
        self.book.attempt(m)
        self.log.count_grasp(self.arm.name)
        held = ' (held at the stop)' if self.belt.held_by(m, pick.contact) else ''
        if held and self.belt.crowded(m, pick.contact, behind=True):
            # Another pressed against it from behind: the belt pauses before the cup comes
            # down, and the queue's pressure with it, until the lift is over
            # (QUEUE_LIFT_PAUSE_LEAD_S). Only the one ahead (the paper's orange behind the
            # purple at the stop): no pause, the belt runs on (it had paused 5 times in 110 of
            # the paper's trials).
            lifted = self._ahead.lift_end if self._ahead is not None else pick.points[-1][0]
            self.belt_pause = (pick.contact + late - QUEUE_LIFT_PAUSE_LEAD_S, lifted)
        self.log.event(now, EventKind.TRACKING, self.arm.name, m, f'contact at {pick.contact:.2f} '
                       f's, x {pick.track(pick.contact)[0]:.3f}{held}; '
                       f'{self.belt.sensed.describe()}')

    def pauses_belt(self, now: float) -> bool:
        """Whether the belt pauses now for a lift out of the end stop's queue."""
        return self.belt_pause[0] <= now <= self.belt_pause[1]

    def _leave_it(self, obs: Observation, m: Material, at_rest: bool = False) -> None:
        """The material cannot be picked before it leaves the belt (``at_rest``: not on the
        move; once the end stop holds it)."""
        self.belt_pause = (math.inf, -math.inf)
        self.book.left_on_belt(m, at_rest)
        self.current = None
        self._ahead = self._pick_plan = None
        if self.state is not LoaderState.WAIT:
            self.enter(LoaderState.WAIT, obs.now, self.s.idle_timeout)

    def _pick_failed(self, obs: Observation, m: Material, why: str) -> None:
        self.belt_pause = (math.inf, -math.inf)
        self.book.give_up(obs.now, m, EventKind.GRASP_FAILED, why, self.arm.name)
        self.book.free_kept(m)          # (a place kept for it is free again)
        self.current = None
        self._ahead = self._pick_plan = None
        self._move(LoaderState.RETREAT, obs, [Waypoint(self.arm.home.copy())])

    def _pick(self, obs: Observation) -> None:
        m, now = known(self.current, 'the material'), obs.now
        if self._arm_pending:
            if now < self.cup.clear_at:
                return
            self._arm_pending = False
            ok, why = self.ports.grip(self.arm.name, True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        if not m.picked and now < m.hands_on:
            self._reaim(obs, m)
        if not m.picked and now >= self._leave and self.arm.holding(obs):
            # Off the belt from here: what the belt queued behind it moves on.
            self.belt.lifted(m, now)
            self.log.count_grasp(self.arm.name, success=True)
            self.log.event(now, EventKind.PICKED, self.arm.name, m, f'attempt {m.attempts}')
            if self._ahead is not None:        # on its way to the place already
                self.cup.adopt(*self._ahead.way.rise)
                self._ahead = None
                return self.enter(LoaderState.PLACE, now, self.arm.motion.end - now
                                  + self.s.settle_margin)
        elif not m.picked and now >= self._leave and self._ahead is not None:
            self._stop_at_lift(obs)
        arrived = self.arrival(obs)
        if arrived is not None:
            self._picked_or_not(obs, m, arrived)

    def _reaim(self, obs: Observation, m: Material) -> None:
        """Correction until contact: the pick re-aimed (``PickPlanner.reaim``) goes on from the
        running motion's sample; one that cannot be is said once, and goes on as it was."""
        pick, now = self._pick_plan, obs.now
        if pick is None or pick.m is not m:
            return
        new = self.planner.reaim(obs, pick, self.arm.motion.points)
        if isinstance(new, str):
            pick.reaim_from = math.inf          # (said once: the pick goes on as it was)
            if abs(pick.reaimed) > CALL_OFF_M and self.arm.stop(now + self.s.plan_latency):
                # Called off: the arm stops where it is, the cup off; once still, the attempt
                # is judged missed (_picked_or_not: another, from what the camera sees from
                # now on, or at rest at the end stop), not 1.5 s later at the lift point.
                self.ports.grip(self.arm.name, False)
                self.book.coming_down(m, math.inf)
                self._ahead = self._pick_plan = None
                self._leave = math.inf
                self.deadline = self.arm.motion.end + self.s.settle_margin
                new = new.replace('the pick goes on', 'called off')
            self.log.event(now, EventKind.REPLANNED, self.arm.name, m, new)
        elif new is not None:
            self._ahead = self.planner.onward(obs, new)
            self.arm.send_continuing(now, known(new.moving, 'the sample')[0], new.points)
            self._leave = new.contact + new.timing.dwell
            self.book.coming_down(m, new.hover_at - REAIM_LEAD_S)
            self._pick_plan = new
            self.log.event(now, EventKind.REPLANNED, self.arm.name, m,
                           f're-aimed {new.reaimed * 1000:+.1f} mm: contact at '
                           f'{new.contact:.2f} s, x {new.contact_x:.3f}; '
                           f'{self.belt.sensed.describe()}')

    def _stop_at_lift(self, obs: Observation) -> None:
        """Not held after the dwell: the motion ends at the lift point instead, at rest, where
        a missed grasp is judged."""
        now = obs.now
        ahead = known(self._ahead, 'the way ahead')
        self._ahead = None
        points = self.arm.motion.points
        q_now = min(points, key=lambda p: abs(p[0] - now))[1]
        after = [p for p in points if p[0] > now + self.s.plan_latency]
        if float(np.max(np.abs(self.arm.q(obs) - q_now))) > FOLLOW_TOLERANCE or not after:
            self.deadline = ahead.lift_end + self.s.settle_margin
        else:
            # From where the motion has the arm at its next sample, moving, to rest at the
            # lift point: the motion's own samples until then, and the stop from there.
            t1, q1, v1, a1 = after[0]
            stop = plan(q1, [Waypoint(ahead.q_lift)], self.arm.limits, t1, v0=v1, a0=a1)
            self.arm.send_continuing(now, t1, stop.points())
            self.deadline = self.arm.motion.end + self.s.settle_margin

    def _picked_or_not(self, obs: Observation, m: Material, arrived: bool) -> None:
        """The pick's motion is over (``arrived``: at its end): on to the place with the
        material held, or another attempt, or a failure."""
        now = obs.now
        if arrived and self.arm.holding(obs):
            if not m.picked:                     # (held, but only sealed after the lift began)
                self.belt.lifted(m, now)
                self.log.count_grasp(self.arm.name, success=True)
                self.log.event(now, EventKind.PICKED, self.arm.name, m, f'attempt {m.attempts}')
            return self._plan_place(obs, m)
        self.ports.grip(self.arm.name, False)
        if m.picked:
            return self._place_failed(obs, m, 'dropped while lifting it' if arrived
                                      else 'the arm did not reach the lift point')
        if not arrived:
            # (Real time: the simulator took the motion in too late and refused it.) The
            # material rides on, untouched: another attempt, like a missed grasp.
            self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                           f'pick attempt {m.attempts} not completed')
            why = 'the arm did not reach the material'
        else:
            self.log.event(now, EventKind.GRASP_MISSED, self.arm.name, m, f'attempt {m.attempts}')
            why = f'not held after {m.attempts} attempts'
        # Another attempt, from what the camera sees of it from now on; once max_retries more
        # have missed, it rides on to the end stop (if not there yet) and is picked there at rest
        # (435 of 445 picks at the stop took their material in the perturbed belt-speed sweep,
        # against 75 % on the move at 0.14 m/s), with as many attempts again; then given up.
        self.book.coming_down(m, math.inf)
        at_rest = m.at_rest_from >= 0
        tries = m.attempts - (m.at_rest_from if at_rest else 0)
        if tries <= self.s.max_retries:
            return self._plan_pick(obs, m)
        if at_rest or not self.layout.end_stop:
            return self._pick_failed(obs, m, why + (
                f' ({tries} at rest at the end stop)' if at_rest else ''))
        # (Also one whose last attempt was made as it came to rest there, or at rest: the
        # misses of the perturbed sweep's at 0.14-0.17 m/s were picks far out of the camera's
        # view, the second as it reached the stop.)
        self.log.event(now, EventKind.REPLANNED, self.arm.name, m,
                       f'{tries} attempts missed: picked again at rest at the end stop')
        self._leave_it(obs, m, at_rest=True)

    def _plan_place(self, obs: Observation, m: Material) -> None:
        """From the lift point over to above the place and down until the material is just
        above it, in one motion; the release and the rise follow once the arm is there. (A
        pick's motion goes on to the place by itself: this is for a material held only once the
        arm was at the lift point.)"""
        way = self.planner.place_way(m, self.planner.lift_point, self.planner.plate_pose(obs),
                                     self.arm.motion.goal)
        if isinstance(way, str):
            return self._place_failed(obs, m, way)
        self.cup.adopt(*way.rise)
        q = self.arm.q(obs)
        self.move(LoaderState.PLACE, obs, self.planner.clear_of_belt(
            m, q, way, lambda waypoints: self.arm.plan(q, waypoints)))

    def _place_failed(self, obs: Observation, m: Material, why: str) -> None:
        self.ports.grip(self.arm.name, False)
        self._pick_failed(obs, m, why)

    def _place(self, obs: Observation) -> None:
        m, now = known(self.current, 'the material'), obs.now
        if not self.arm.holding(obs):
            return self._place_failed(obs, m, 'dropped on the way to its place')
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if not arrived:
            return self._place_failed(obs, m, 'the arm did not reach the place')
        ok, why = self.ports.grip(self.arm.name, False)
        if not ok:
            return self._place_failed(obs, m, f'release failed: {why}')
        if not self.layout.carried(m.color):
            self.book.placed(m)
            self.log.event(now, EventKind.PLACED, self.arm.name, m,
                           f'{self.layout.destination(m.color)} slot {m.place}')
        else:
            self.book.loaded_on_plate(m)
            self.log.event(now, EventKind.LOADED, self.arm.name, m, f'plate slot {m.slot}')
        # The cup stays still while the vacuum lets go, then rises: as the start of the next
        # motion, planned now.
        self.current = None
        self.cup.released()
        self.enter(LoaderState.WAIT, now, self.s.idle_timeout)
        self._wait(obs)

    def _when_there(self, what: str, then: LoaderState, obs: Observation) -> None:
        """A motion to ``what`` (a rise, a retreat, home): once it is over, ``then``."""
        if self.motion_over(obs, what):
            self.enter(then, obs.now, math.inf if then is LoaderState.DONE
                       else self.s.idle_timeout)
