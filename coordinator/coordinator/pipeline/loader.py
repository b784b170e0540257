"""The loader: the Zu 12 picks materials off the running belt and sets them down."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import (
    Any,
    Callable,
    List,
    Optional,
    Sequence,
    Tuple,
    Union,
)

import numpy as np

from controllers.bezier import Pose2D
from controllers.pick_place import PickTiming, follow_pick
from controllers.time_optimal import (
    SAMPLE_PERIOD_S,
    PlanError,
    TooLate,
    Waypoint,
    plan,
    timed_path,
)
from coordinator.layout import CellLayout, slot_in_world
from coordinator.pipeline.arm import Arm
from coordinator.pipeline.belt import BeltModel
from coordinator.pipeline.machine import Machine, transition_table
from coordinator.pipeline.materials import MaterialBook
from coordinator.pipeline.model import (
    DOWN,
    EDGE_CLEARANCE_M,
    FOLLOW_TOLERANCE,
    MAX_REPLANS,
    PICK_LEAD_S,
    PICK_REPLAN_STEP_S,
    PICK_TRIES,
    PLAN_MARGIN,
    QUEUE_LIFT_PAUSE_LEAD_S,
    RELEASE_HOLD_S,
    SETTLE_S,
    EventKind,
    LoaderState,
    Material,
    MaterialStatus,
    Observation,
    Points,
    Ports,
    Settings,
    known,
)
from coordinator.pipeline.pick_geometry import (
    continuous,
    edge_point,
    lift_line,
    over_the_belt,
    place_points,
)
from coordinator.pipeline.record import EventLog

# What the Zu 12 lifts out of the end stop's queue rises this far over the tallest material
# that can stand next to it before it swings away [m].
QUEUE_SWING_CLEARANCE_M = 0.05
# A material met at rest in the end stop's queue is met this long after its belt pause began,
# and that no sooner than it came to rest there [s].
QUEUE_REST_S = 0.1


@dataclass
class PlaceWay:
    """A held material's way onto its place (joints), and the rise from there."""
    waypoints: List[Waypoint]     # from the lift point: over the belt's edge, above, down
    then: np.ndarray              # where the cup rises to over the place (not to a pick)
    above: np.ndarray             # above the place (x, y, z)
    above_q: np.ndarray
    onto_plate: bool


@dataclass
class Ahead:
    """A pick's motion that goes on to the place: the way there, and the lift point it passes
    on the way."""
    way: PlaceWay
    q_lift: np.ndarray
    lift_end: float               # (about when it passes it)


# A pick that cannot be made before the material leaves the belt.
LEAVE = 'leave'


@dataclass
class PickPlan:
    """A pick as it is planned: its material and timing, where the belt takes the material, and
    the motion to meet it there (joints over it, over the belt's edge, at the lift point)."""
    m: Material
    timing: PickTiming
    track: Callable[[float], np.ndarray]
    start: float                  # when the motion starts
    contact: float                # when the cup is on the material
    q_hover: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q_edge: Optional[np.ndarray] = None
    q_lift: np.ndarray = field(default_factory=lambda: np.zeros(0))
    waypoints: List[Waypoint] = field(default_factory=list)
    points: Points = field(default_factory=list)


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
    """The Zu 12: picks materials off the running belt (meeting each where it will be, and
    moving with it while the cup is on it); a class it places itself onto its destination once
    it has ridden to the end stop, the carried ones onto the youBot's plate."""

    state: LoaderState

    name = 'loader'
    TRANSITIONS = LOADER_TRANSITIONS

    def __init__(self, arm: Arm, book: MaterialBook, belt: BeltModel, log: EventLog,
                 layout: CellLayout, settings: Settings, ports: Ports,
                 youbot_loading: Callable[[], bool]) -> None:
        """``youbot_loading``: the one question the Zu 12 asks of the youBot, whether it
        waits at home for its load."""
        super().__init__(arm, log, settings, LoaderState.START)
        self.book, self.belt, self.layout, self.ports = book, belt, layout, ports
        self.youbot_loading = youbot_loading
        self.lag = 0.0                    # the longest a pick's plan has taken (real time) [s]
        self.current: Optional[Material] = None     # the material being picked or placed
        self._then: Optional[np.ndarray] = None     # where the cup rises to from its place
        self._above: Optional[np.ndarray] = None    # above the place (x, y, z), joints
        self._above_q: Optional[np.ndarray] = None
        self._lift: Optional[np.ndarray] = None     # the last pick's lift point (x, y, z)
        self._onto_plate = False                    # the last place was on the youBot's plate
        self._clear: Optional[np.ndarray] = None    # clear of the place once here (joints)
        self._leave = math.inf                      # when the cup lifts the material
        self._ahead: Optional[Ahead] = None         # the pick's motion goes on to the place
        self._replans = 0                           # pick plans the port started late
        # The cup has just let go on the plate or the ground target: the next motion rises
        # first (straight up, after the release hold), whatever it is.
        self._at_release = False
        self._clear_at = -math.inf                  # when the cup is clear of the place
        self._arm_pending = False                   # the cup goes on once it is clear
        # When the belt pauses for a lift out of the end stop's queue (from, to) [s].
        self.belt_pause: Tuple[float, float] = (math.inf, -math.inf)
        S = LoaderState
        self.handlers = {S.WAIT: self._wait, S.PICK: self._pick, S.PLACE: self._place,
                         S.RISE: self._rise, S.RETREAT: self._retreat, S.HOME: self._home,
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
        if m is not None:
            self._plan_pick(obs, m)
        if self.state is LoaderState.WAIT and self._at_release:
            # Nothing to pick yet: up from the place, to wait there.
            self._move(LoaderState.RISE, obs, [])

    def _move(self, state: LoaderState, obs: Observation, waypoints: List[Waypoint],
              start: Optional[float] = None) -> None:
        """Send a motion through ``waypoints`` (planned from rest where the arm is); from a
        place the cup has just let go at, it first stays still while the material falls free
        and rises straight up."""
        points = self._plan(obs, waypoints, start)
        self.move(state, obs, points, start)
        self._after_send()

    def _plan(self, obs: Observation, waypoints: List[Waypoint],
              start: Optional[float] = None, edge: Optional[np.ndarray] = None) -> Points:
        """From a release: the hold, then straight up to above the place and over the belt's
        edge at ``edge`` (joints; towards a pick), or without it up to the carry height."""
        waypoints, wait = self._from_release(waypoints, edge)
        if self._at_release:
            # Clear of the place once straight above it: the cup may be switched on there
            # (what it let go is place_height below it), and the youBot may leave.
            self._clear = self._above_q
        return self.arm.plan(self.arm.q(obs), waypoints, wait, start)

    def _from_release(self, waypoints: List[Waypoint], edge: Optional[np.ndarray] = None
                      ) -> Tuple[List[Waypoint], float]:
        """``waypoints``, after the rise from a place the cup has just let go at (see _plan),
        and how long the motion waits first."""
        if not self._at_release:
            return list(waypoints), 0.0
        rise = self.s.timing.place_descend
        if edge is not None:
            above = known(self._above_q, 'the point above the place')
            # (Up over the place first where the swing from there to the edge would bulge out
            # over the belt, low: see _place_way.)
            then = known(self._then, 'the rise from the place')
            over = ([Waypoint(then, stop=False)] if over_the_belt(self.layout, above, edge, 0.0)
                     and float(np.max(np.abs(then - above))) > 1e-6 else [])
            first = [Waypoint(above, stop=False, min_time=rise), *over,
                     Waypoint(edge, stop=False)]
        else:
            # Straight up over the place first (over what else is there: a swing from the
            # release towards home swept two materials off their slots beside it), then on.
            above = known(self._above_q, 'the point above the place')
            then = known(self._then, 'the rise from the place')
            first = [Waypoint(above, stop=False, min_time=rise)]
            if float(np.max(np.abs(then - above))) > 1e-6:
                first.append(Waypoint(then, stop=not waypoints))
            elif not waypoints:
                first = [Waypoint(above, min_time=rise)]
        return first + list(waypoints), RELEASE_HOLD_S

    def _after_send(self) -> None:
        if self._at_release:
            self._at_release = False
            self._clear_at = self.arm.arrival_time(known(self._clear, 'the clear point'))

    def clear_of_the_plate(self, now: float) -> bool:
        """Whether the cup is away from the youBot's plate: not placing there, nor rising from
        it, nor swinging home (over it)."""
        return (self.state not in (LoaderState.PLACE, LoaderState.RISE, LoaderState.HOME)
                and not self._at_release and now >= self._clear_at)

    def loadable(self, m: Material) -> bool:
        """Whether the Zu 12 may put ``m`` onto the youBot's plate now: it waits at home, and
        has a slot for it."""
        return self.youbot_loading() and bool(self.book.plate_slots(m))

    def _next(self, waiting: Sequence[Material]) -> Optional[Material]:
        """The next material to pick: the most downstream one bound for the youBot's plate (the
        youBot waits for them); one the Zu 12 places itself once the end stop holds it (it
        rides to the end)."""
        ride = self.layout.end_stop
        carried = [m for m in waiting if self.layout.carried(m.color)]
        # (The youBot takes a load only while it waits at home, with room on its plate: the
        # others ride on, and queue at the end stop until it is back.)
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
        why = self._approach(obs, pick) or self._meet(obs, pick)
        if why == LEAVE:
            return self._leave_it(obs, m)
        if why:
            return self._pick_failed(obs, m, why)
        self._onward(obs, pick)
        self._send_pick(obs, pick, lag, spent)

    def _approach(self, obs: Observation, pick: 'PickPlan') -> str:
        """The joints over the material at a first guess of the contact time, and over the
        belt's edge on the way there from a place; the contact no sooner than the arm can be
        there. Why not, if it cannot be."""
        m, timing = pick.m, pick.timing
        seed = self.arm.motion.goal if self.arm.has_motion else self.arm.q(obs)
        # The hover point moves with the contact time: a first guess from a rest-to-rest move
        # there, then later by a little until the arm makes it.
        hover = follow_pick(pick.track, pick.contact, m.size, timing)[0][0][1]
        q_hover = self.arm.solve(hover, DOWN, 'world', seed)
        if q_hover is None:
            return 'no IK solution for the pick'
        pick.q_hover = q_hover
        # From a place: back over the belt's edge on the way to the hover point.
        if self._at_release and self._above is not None:
            # (From the plate: round the arc, the cup clear of what rides on the belt.)
            lay, above = self.layout, self._above
            edge = (edge_point(lay, hover, above, m.size + EDGE_CLEARANCE_M, arc=True)
                    if self._onto_plate else edge_point(lay, hover, above, EDGE_CLEARANCE_M))
            pick.q_edge = self.arm.solve(edge, DOWN, 'world',
                                         known(self._above_q, 'the point above the place'))
        # (A first guess: the way to the hover point, at rest there; a plan that cannot make
        # it says by how much.)
        way, wait = self._from_release([Waypoint(q_hover)], pick.q_edge)
        reach = wait + plan(self.arm.q(obs), way, self.arm.limits).end
        pick.contact = max(pick.contact, pick.start + reach + timing.descend)
        return ''

    def _not_as_it_queues(self, m: Material, contact: float, timing: PickTiming) -> float:
        """The contact, or later: not while the material comes to rest against another in the
        end stop's queue, between the cup's contact and the lift. Met on the move there, the
        cup carried a 50 mm blue on into the purple the stop held (the camera's estimate 4 mm
        behind), pressed it, and the lift dragged the purple up and off the belt's end. It is
        met once at rest there instead (the belt pauses around that lift; the pause begins
        QUEUE_LIFT_PAUSE_LEAD_S before the contact, after it has come to rest)."""
        belt = self.belt
        rest = belt.comes_to_rest(m)
        # (Resting there by the contact but not yet as the pause begins, it would stop short.)
        begins = contact - QUEUE_LIFT_PAUSE_LEAD_S - QUEUE_REST_S
        if begins < rest <= contact + timing.dwell + timing.lift and belt.crowded(m, rest):
            return rest + QUEUE_LIFT_PAUSE_LEAD_S + QUEUE_REST_S
        return contact

    def _lifting(self, pick: 'PickPlan') -> PickTiming:
        """The pick's timing, its lift high enough out of the end stop's queue for what it holds
        to pass QUEUE_SWING_CLEARANCE_M over the tallest material that can be next to it: the
        swing on from the lift point sags and bulges outwards as it begins (a green lifted
        7 cm from behind an orange came down 1.3 cm and 2 cm sideways onto it, and knocked it
        over)."""
        m, timing = pick.m, pick.timing
        if not (self.belt.held_by(m, pick.contact) and self.belt.crowded(m, pick.contact)):
            return timing
        high = self.layout.material_size + QUEUE_SWING_CLEARANCE_M
        return replace(timing, lift_height=max(timing.lift_height, high))

    def _meet(self, obs: Observation, pick: 'PickPlan') -> str:
        """The pick's motion (``pick.points``), its contact moved later until the arm makes
        it; why not (or LEAVE: the material leaves the belt first)."""
        m, timing, track = pick.m, pick.timing, pick.track
        refused = ''
        for _ in range(PICK_TRIES):
            if track(pick.contact)[0] < self.s.pick_x - 1e-6:
                pick.contact = self.belt.reaches(m, self.s.pick_x)
            pick.contact = self._not_as_it_queues(m, pick.contact, timing)
            if track(pick.contact + timing.dwell)[0] > (self.layout.belt_end_x - m.size / 2
                                                        + 1e-6):
                return LEAVE                   # off the end (no stop) before the cup is on it
            path, lift = follow_pick(track, pick.contact, m.size, self._lifting(pick),
                                     SAMPLE_PERIOD_S)
            self._lift = np.asarray(lift, float)
            qs = self._solve_along(path, lift, pick.q_hover)
            if qs is None:
                return 'no IK solution for the pick path'
            if not continuous([pick.q_hover, qs[0]]):
                pick.q_hover = qs[0]            # (on the other branch, solved from the end)
            times = np.array([t for t, _ in path])
            q_path = np.array(qs[:-1])
            v = np.gradient(q_path, times, axis=0, edge_order=2)
            a = np.gradient(v, times, axis=0, edge_order=2)
            # To the hover point at its time, with the path's velocity; along the path (sent as
            # it is); then up to the lift point, at rest, as fast as the joints allow.
            waypoints = [Waypoint(q_path[0], velocity=v[0], acceleration=a[0], at=times[0])]
            waypoints += [Waypoint(q, velocity=vk, acceleration=ak, at=tk, direct=True)
                          for q, vk, ak, tk in zip(q_path[1:], v[1:], a[1:], times[1:])]
            waypoints += self._lift_way(m, pick, path[-1][1], q_path[-1], times[-1], qs[-1])
            pick.waypoints, pick.q_lift = waypoints, qs[-1]
            try:
                pick.points = self._plan(obs, waypoints, pick.start, pick.q_edge)
                return ''
            except TooLate as too_late:
                pick.contact += max(too_late.by, 0.0) + PICK_LEAD_S / 2
            except PlanError as exc:
                # The joints' path along this stretch of the track is out of the limits (the
                # IK changes branch somewhere on it): meet the material a little further on.
                refused = f'no motion for the pick: {exc}'
                pick.contact += PICK_REPLAN_STEP_S
        return refused or 'the arm cannot meet the material in time'

    def _lift_way(self, m: Material, pick: 'PickPlan', on: np.ndarray, q_on: np.ndarray,
                  t_on: float, q_lift: np.ndarray) -> List[Waypoint]:
        """From the dwell (the cup on the material at ``on``, joints ``q_on``, at ``t_on``) up
        to the lift point: as fast as the joints allow; out of the end stop's queue, with
        another material right behind, straight up along the line, timed along it
        (timed_path). The joints' own way from the dwell to the lift point bowed 1.8 cm
        upstream as it began, into the material behind, and lifted the queue with it (the
        ones behind rose up to 4 cm and fell back turned 23 degrees)."""
        timing = pick.timing
        if not (self.belt.held_by(m, pick.contact) and self.belt.crowded(m, pick.contact)):
            return [Waypoint(q_lift, min_time=timing.lift)]
        points = lift_line(on, self._lift) if self._lift is not None else []
        line = self.arm.solve_path(points, q_on) if points else []
        if line is None or not continuous([q_on, *line, q_lift]):
            return [Waypoint(q_lift, min_time=timing.lift)]
        try:
            return timed_path([q_on, *line, q_lift], self.arm.limits, t_on,
                              min_time=timing.lift)
        except PlanError:
            return [Waypoint(q_lift, min_time=timing.lift)]

    def _solve_along(self, path: Any, lift: np.ndarray, seed: np.ndarray
                     ) -> Optional[List[np.ndarray]]:
        """Joints along a pick's path and at its lift point, on one IK branch: near the Zu 12's
        base its elbow can flip between two samples (a path the planner refuses, "joint 3
        acceleration -320"); then the whole path is solved again from its end backwards, on
        the branch the end is on. None if neither is continuous."""
        points = [p for _, p in path] + [lift]
        qs = self.arm.solve_path(points, seed)
        if qs is None or continuous(qs):
            return qs
        back = self.arm.solve_path(points[::-1], qs[-1])
        if back is None or not continuous(back):
            return None
        return back[::-1]

    def _onward(self, obs: Observation, pick: 'PickPlan') -> None:
        """On to the place in the same motion, through the lift point without stopping there:
        the swing starts during the lift, and the place does not wait for an arrival check at
        the lift point and a plan after it. (A missed grasp stops the arm at the lift point
        instead: see _pick.)"""
        m = pick.m
        self._ahead = None
        place_way = self._place_way(m, self._lift, obs.youbot_pose, pick.q_lift)
        if isinstance(place_way, str):
            return                      # (the place is planned, or its failure told, later)
        # Lifted out of a queue (at the end stop), it comes to rest at the lift point, clear
        # of its neighbours' tops, before it swings: a swing begun during the lift dragged a
        # purple into the green queued behind it (the arm stalled, the purple fell back onto
        # the belt).
        crowded = self.belt.crowded(m, pick.contact)
        through = (pick.waypoints if pick.waypoints[-1].direct else   # (straight up: _lift_way)
                   pick.waypoints[:-1] + [Waypoint(pick.q_lift, stop=crowded,
                                                   min_time=pick.timing.lift)])
        try:
            whole = self._plan(obs, through + place_way.waypoints, pick.start, pick.q_edge)
        except PlanError:
            return                      # (the place is planned at the lift point then)
        self._ahead = Ahead(place_way, pick.q_lift, pick.points[-1][0])
        pick.points = whole

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
        self._arm_pending = self._at_release
        if not self._arm_pending:
            ok, why = self.ports.grip(self.arm.name, True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        self._after_send()
        self._leave = pick.contact + pick.timing.dwell + late
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
                       f's, x {pick.track(pick.contact)[0]:.3f}{held}')

    def pauses_belt(self, now: float) -> bool:
        """Whether the belt pauses now for a lift out of the end stop's queue."""
        return self.belt_pause[0] <= now <= self.belt_pause[1]

    def _leave_it(self, obs: Observation, m: Material) -> None:
        """The material cannot be picked before it leaves the belt."""
        self.belt_pause = (math.inf, -math.inf)
        self.book.left_on_belt(m)
        self.current = None
        self._ahead = None
        if self.state is not LoaderState.WAIT:
            self.enter(LoaderState.WAIT, obs.now, self.s.idle_timeout)

    def _pick_failed(self, obs: Observation, m: Material, why: str) -> None:
        self.belt_pause = (math.inf, -math.inf)
        self.book.give_up(obs.now, m, EventKind.GRASP_FAILED, why, self.arm.name)
        self.book.free_kept(m)          # (a place kept for it is free again)
        self.current = None
        self._ahead = None
        self._move(LoaderState.RETREAT, obs, [Waypoint(self.arm.home.copy())])

    def _pick(self, obs: Observation) -> None:
        m, now = known(self.current, 'the material'), obs.now
        if self._arm_pending:
            if now < self._clear_at:
                return
            self._arm_pending = False
            ok, why = self.ports.grip(self.arm.name, True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        if not m.picked and now >= self._leave and self.arm.holding(obs):
            # Off the belt from here: what the belt queued behind it moves on.
            self.belt.lifted(m, now)
            self.log.count_grasp(self.arm.name, success=True)
            self.log.event(now, EventKind.PICKED, self.arm.name, m, f'attempt {m.attempts}')
            if self._ahead is not None:        # on its way to the place already
                self._adopt(self._ahead.way)
                self._ahead = None
                return self.enter(LoaderState.PLACE, now, self.arm.motion.end - now
                                  + self.s.settle_margin)
        elif not m.picked and now >= self._leave and self._ahead is not None:
            self._stop_at_lift(obs)
        arrived = self.arrival(obs)
        if arrived is not None:
            self._picked_or_not(obs, m, arrived)

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
        if not arrived:
            self.ports.grip(self.arm.name, False)
            if m.picked:
                return self._place_failed(obs, m, 'the arm did not reach the lift point')
            # (Real time: the simulator took the motion in too late and refused it.) The
            # material rides on, untouched: another attempt, like a missed grasp.
            self.log.event(now, EventKind.ARM_STALLED, self.arm.name, m,
                           f'pick attempt {m.attempts} not completed')
            if m.attempts <= self.s.max_retries:
                return self._plan_pick(obs, m)
            return self._pick_failed(obs, m, 'the arm did not reach the material')
        if not self.arm.holding(obs):
            self.ports.grip(self.arm.name, False)
            if m.picked:
                return self._place_failed(obs, m, 'dropped while lifting it')
            self.log.event(now, EventKind.GRASP_MISSED, self.arm.name, m, f'attempt {m.attempts}')
            if m.attempts <= self.s.max_retries:
                return self._plan_pick(obs, m)
            return self._pick_failed(obs, m, f'not held after {m.attempts} attempts')
        if not m.picked:                     # (held, but only sealed after the lift began)
            self.belt.lifted(m, now)
            self.log.count_grasp(self.arm.name, success=True)
            self.log.event(now, EventKind.PICKED, self.arm.name, m, f'attempt {m.attempts}')
        self._plan_place(obs, m)

    def _plan_place(self, obs: Observation, m: Material) -> None:
        """From the lift point over to above the place and down until the material is just
        above it, in one motion; the release and the rise follow once the arm is there. (A
        pick's motion goes on to the place by itself: this is for a material held only once the
        arm was at the lift point.)"""
        way = self._place_way(m, self._lift, obs.youbot_pose, self.arm.motion.goal)
        if isinstance(way, str):
            return self._place_failed(obs, m, way)
        self._adopt(way)
        self.move(LoaderState.PLACE, obs, self.arm.plan(self.arm.q(obs), way.waypoints))

    def _place_way(self, m: Material, lift: Optional[np.ndarray], youbot_pose: Pose2D,
                   seed: np.ndarray) -> Union['PlaceWay', str]:
        """The way from the lift point ``lift`` (x, y, z; None: from above the place) onto
        ``m``'s place, or why there is none: over the belt's edge, to ``place_height`` above
        the place, and straight down until the material is just above it."""
        size, lay = m.size, self.layout
        onto_plate = lay.carried(m.color)
        if not onto_plate:
            region = lay.region_of(m.color)
            free = self.book.free_places(region.name, m)
            if not free:
                return f'{region.name} is full (its {len(region.slots)} slots are taken)'
            self.book.keep_place(m, free[0])
            target = region.slots[m.place]
        else:
            free = self.book.plate_slots(m)
            if not free:
                return 'the youBot plate is full'
            self.book.keep_slot(m, free[0])
            target = slot_in_world(youbot_pose, self.layout.plate_slots[m.slot],
                                   self.layout.youbot_base_z, size)
        t = self.s.timing
        # Down onto it from over the materials there already.
        release, above, transfer = place_points(
            target, size, t, self.book.set_down_rise(
                None if onto_plate else lay.destination(m.color)), lay.belt_top)
        # Over the belt's near edge (rather than up to the carry height over the place and down
        # again), what the cup holds 5 cm over what can ride on the belt: onto the plate round
        # the arc (the way crosses the edge near the plate; before that it lies over the
        # belt), onto the ground target on the straight line, 5 cm over the belt's top.
        edge = (transfer if lift is None else
                edge_point(lay, lift, above, 2 * size + EDGE_CLEARANCE_M, arc=True) if onto_plate
                else edge_point(lay, lift, above, size + EDGE_CLEARANCE_M))
        qs = self.arm.solve_path([transfer, above, release, edge], seed)
        if qs is None:
            return 'no IK solution for the place path'
        q_transfer, q_above, q_release, q_edge = qs
        # Over to a place lower than the belt, the joints' way from the edge down to above it
        # can bulge back out over the belt: then through the transfer point (above the place,
        # clear of the belt) first, and straight down from there.
        over = ([Waypoint(q_transfer, stop=False)]
                if over_the_belt(self.layout, q_edge, q_above, size) else [])
        return PlaceWay([Waypoint(q_edge, stop=False), *over, Waypoint(q_above, stop=False),
                         Waypoint(q_release, hold=SETTLE_S, min_time=t.place_descend)],
                        q_transfer, above, q_above, onto_plate)

    def _adopt(self, way: 'PlaceWay') -> None:
        """The place the arm is on its way to: where the cup rises from it to."""
        self._then = way.then
        self._above, self._above_q, self._onto_plate = way.above, way.above_q, way.onto_plate

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
        self.current, self._at_release = None, True
        self.enter(LoaderState.WAIT, now, self.s.idle_timeout)
        self._wait(obs)

    def _rise(self, obs: Observation) -> None:
        if self.motion_over(obs, 'the rise from the place'):
            self.enter(LoaderState.WAIT, obs.now, self.s.idle_timeout)

    def _retreat(self, obs: Observation) -> None:
        if self.motion_over(obs, 'retreat'):
            self.enter(LoaderState.WAIT, obs.now, self.s.idle_timeout)

    def _home(self, obs: Observation) -> None:
        if self.motion_over(obs, 'home'):
            self.enter(LoaderState.DONE, obs.now, math.inf)
