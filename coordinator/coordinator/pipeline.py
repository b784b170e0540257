"""The pipeline run as an explicit state machine (no ROS): sorting, delivery and transport.

Two machines share one clock. The loader (the Zu 12) watches the vision's detections, picks each
material off the running belt with the suction cup, sets the ones its class's rule has it place
down on their destination's next free slot, and loads the ones the youBot carries onto its
plate. The transport (the youBot) waits for its load, drives along Bezier paths with a PD
follower, unloads with its arm (into the pool from over its wall, onto any other destination's
next free slot) and drives home. Both arms end at their start poses. Which class goes where is
the world file's (coordinator.layout's rules): no class is named here.

The machine acts through ``Ports`` (IK, trajectories, suction, belt, base twist, events) and
sees the world through ``Observation``; the node implements both over ROS, tests fake them.
Every state has a deadline; a missed grasp is retried, then reported; a material that goes off
the belt end is reported; a port that stops answering (``NodeTimeout``) ends the run. The run
always ends with a ``RunResult``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import (
    Callable,
    Dict,
    List,
    Optional,
    Protocol,
    Sequence,
    Set,
    Tuple,
    TypeVar,
    Union,
)

import numpy as np

from controllers import youbot_arm, zu12_arm
from controllers.arrays import Vector
from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.conveyor import Item, advance, held
from controllers.path_follower import PathFollower, PDGains, TurnLimits
from controllers.pick_place import PickTiming, follow_pick
from controllers.time_optimal import (
    SAMPLE_PERIOD_S,
    JointLimits,
    PlanError,
    TooLate,
    Waypoint,
    plan,
    timed_path,
)
from controllers.youbot_kinematics import YoubotKinematics
from coordinator.layout import (
    GRASP_STANDOFF_M,
    PLATE_SLOTS_IN_BASE_M,
    PLATE_TOP_IN_BASE_M,
    POOL,
    CellLayout,
    slot_in_world,
    slot_row,
    world_to_base,
)
from coordinator.reach import youbot_tool_quaternion

DOWN = (1.0, 0.0, 0.0, 0.0)                  # tool z pointing down (x, y, z, w)
# A pick's contact is planned at least this long after the arm could be over the material, and
# moved this much later while the arm cannot make it [s].
PICK_LEAD_S = 0.1
# The Zu 12 crosses the belt's near edge this far outside it, with what it carries (or its
# empty cup) at least this far above the belt's top [m].
EDGE_CLEARANCE_M = 0.05
PICK_TRIES = 6
# Real time: a pick allows for this much more than the longest plan of one has taken (the next
# may need a few more IK calls).
PLAN_MARGIN = 1.25
# A pick the port starts late is planned again this many times at most.
MAX_REPLANS = 2
# A released material falls free of the cup or the fingers before the tool moves on [s]: it has
# dropped 5 cm by then, and the tool's next motion starts from rest (0.2 s cost 0.1 s a cycle).
RELEASE_HOLD_S = 0.1
# A motion that ends where the tool grips or lets go holds its goal this long, so that the arm
# has settled there [s]. Its arrival is judged on joint feedback as well (within
# ``arrive_tolerance`` and at rest), so the hold need only cover a control period or so
# (0.15 s cost about a second per run over the 15 grasps and releases).
SETTLE_S = 0.05
# A material on the belt with another this near (between their faces, along the belt) is lifted
# clear of it before it swings away [m].
QUEUE_CLEARANCE_M = 0.03
# The belt stops while the end stop's queue reaches back to this far past the pick point (or,
# without a stop, a material that must wait comes this near its end) [m].
QUEUE_MARGIN_M = 0.15
# An arm farther than this from where its motion has it now is not following it [rad].
FOLLOW_TOLERANCE = 0.1
# A motion's samples: (absolute time [s], joint positions, velocities, accelerations).
Points = List[Tuple[float, np.ndarray, np.ndarray, np.ndarray]]
T = TypeVar('T')


def known(value: Optional[T], what: str) -> T:
    """``value``, which the state machine has set by now (a RuntimeError naming ``what`` if
    a change broke that)."""
    if value is None:
        raise RuntimeError(f'{what} is not known in this state')
    return value


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
    zu12_armed: bool = False      # the grip tool is switched on (its state, as last published)
    youbot_armed: bool = False
    zu12_dq: Optional[np.ndarray] = None       # measured joint velocities, if known
    youbot_dq: Optional[np.ndarray] = None


@dataclass(frozen=True)
class Event:
    time: float
    kind: str                     # seen, stopped_belt, picked, placed, delivered, ...
    robot: str = ''
    material: int = -1
    color: str = ''
    detail: str = ''


class Ports(Protocol):
    def solve(self, arm: str, position: Vector, orientation: Vector,
              frame: str, seed: Vector) -> Tuple[Optional[np.ndarray], str]:
        """Joint positions for the tool at a pose, or (None, why). Raises NodeTimeout."""

    def trajectory(self, arm: str, points: Points, start: float,
                   continuing: bool = False) -> float:
        """Send an arm motion whose first segment begins at ``start`` (points: absolute times).
        Returns how much later than planned the port scheduled the whole motion [s]: 0 in
        lock-step; in real time, a plan that took longer than its latency allowance starts
        later, whole, rather than with a first segment too short for the joints' limits.
        ``continuing``: the motion goes on from the arm's running one (its first points are
        that motion's samples, ``start`` may be past): sent as it is, never later (0)."""

    def grip(self, arm: str, on: bool) -> Tuple[bool, str]:
        """Arm (on) or release (off) the arm's gripping tool. Raises NodeTimeout."""

    def belt(self, speed: float) -> Optional[float]:
        """Set the belt speed; returns the (simulated) time it took effect if that is later
        than the decision (real time), or None (lock-step: at once). Raises NodeTimeout."""

    def drive(self, vx: float, vy: float, wz: float) -> None: ...

    def follow(self, follower: Optional[PathFollower]) -> bool:
        """Have the base controller run ``follower`` on every odometry message (None: stop
        that). True if the port does so (real time: a decision held up by IK calls for the
        other arm must not leave the base running on a stale command), and the pipeline's
        ticks only judge the drive; False if the ticks send its commands (lock-step, where a
        decision sees every state)."""

    def event(self, event: Event) -> None: ...


@dataclass(frozen=True)
class Settings:
    pick_x: float = -0.6              # the Zu 12 picks materials downstream of this x [m]
    confirm_hits: int = 8             # frames a track needs before it is acted on
    max_retries: int = 1              # extra grasp attempts on a missed grasp
    zu12_scaling: float = 1.0         # fraction of the Zu 12's joint speed limits
    youbot_scaling: float = 1.0
    arrive_tolerance: float = 0.03    # joint error [rad] that counts as arrived
    rest_speed: float = 0.05          # joint speed [rad/s] below which an arm is at rest
    settle_margin: float = 2.0        # a motion may end this late before it is a failure [s]
    drive_margin: float = 15.0        # a drive may end this late [s]
    idle_timeout: float = 20.0        # belt running, nothing new to pick: loading is over [s]
    run_timeout: float = 300.0        # the whole run [s]
    drive_speed: float = 0.7          # the dummy's speed along a path [m/s]
    # Its heading's turn rate and acceleration, at most: a half turn (between the stands, and
    # home) takes 3.1 s, within the follower's and the base's limits (below; the base's
    # acceleration limit is 2 rad/s^2) [rad/s, rad/s^2].
    drive_turn: float = 1.3
    drive_turn_accel: float = 1.8
    # The follower's command limits, within the youBot's (0.8 m/s each of vx, vy; 1.5 rad/s):
    # a margin over the path's speed and the heading's turn rate to correct with.
    base_max_speed: float = 0.75
    base_max_turn: float = 1.45
    # A motion starts this much later than planned-for "now" (real time: the plan's IK calls
    # and the message's trip; a late first segment would be too fast and rejected) [s].
    plan_latency: float = 0.0
    drive_accel: float = 0.8          # [m/s^2]
    # The shortest times of the moves near a material (the time-optimal plan may take longer):
    # gentle enough that the cup and the fingers do not knock it.
    timing: PickTiming = PickTiming(hover=0.06, descend=0.3, dwell=0.15, lift=0.2,
                                    lift_height=0.07, place_descend=0.15,
                                    place_height=0.07)


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
    # The vision's detection that confirmed it, as reported: its colour and where the frame
    # showed it, at the frame's stamp (``position`` is carried on by the belt model).
    detection: Optional[Detection] = None
    size: float = 0.05            # its class's cube edge [m]
    place: int = -1               # its slot at its destination, once one is kept for it


@dataclass
class Motion:
    """A planned arm motion. Whether it is over is judged from joint feedback (``arrived``):
    its end time as scheduled, and the measured joints at its goal."""
    arm: str
    points: Points
    start: float = math.nan       # when its first segment begins

    def delay(self, seconds: float) -> None:
        """Shift the whole motion later (the port scheduled it later than planned)."""
        self.points = [(t + seconds, q, v, a) for t, q, v, a in self.points]
        self.start += seconds

    @property
    def end(self) -> float:
        return self.points[-1][0]

    @property
    def goal(self) -> np.ndarray:
        return self.points[-1][1]


@dataclass
class RunResult:
    status: str                        # completed, incomplete, timeout, node_timeout, error
    completion_time: float             # sim time from start to both robots home [s]
    total: int
    identified: int                    # materials the vision reported with a colour
    picked: int                        # materials the Zu 12 lifted off the belt
    delivered: int                     # materials at their destination (as the machine saw it)
    grasp_attempts: int                # both arms
    grasp_successes: int
    missed: int                        # went off the belt end unpicked
    failed: int
    message: str = ''
    materials: List[Dict] = field(default_factory=list)
    # Per arm, as the paper splits its rates: the Zu 12's picks, the youBot's unloads.
    zu12_grasp_attempts: int = 0
    zu12_grasp_successes: int = 0
    youbot_grasp_attempts: int = 0
    youbot_grasp_successes: int = 0
    loaded: int = 0                    # materials the Zu 12 set down on the youBot's plate
    trips: int = 0                     # loads the youBot set off with
    belt_stops: int = 0                # times the belt stopped while loading (a full queue)


class LoaderState(Enum):
    """The Zu 12's states: wait for the front material at the pick point; pick it (down onto it
    with the cup switched on), lift it, take it down to its place, release it and rise; retreat
    after a failure; home and done once loading is over. Each motion's end is judged from joint
    feedback, and the next one is planned from there."""
    START = 'start'
    WAIT = 'wait'
    PICK = 'pick'
    PLACE = 'place'
    RISE = 'rise'
    RETREAT = 'retreat'
    HOME = 'home'
    DONE = 'done'


class TransportState(Enum):
    """The youBot's states: wait for its load, drive; per material: down onto it and grip,
    carry it over its destination, let go; then drive home (the arm rising to its carry pose
    as the base sets off), fold. The base's drive goes on whatever the arm does: on the way to
    a stand the arm takes the first material it unloads there (it rides on the base's plate),
    and holds it up until the base stands."""
    WAIT_LOAD = 'wait_load'
    DRIVE = 'drive'
    GRASP = 'grasp'
    CARRY = 'carry'
    RELEASE = 'release'
    FOLD = 'fold'
    DONE = 'done'


class Machine:
    """One robot's state machine: its state, that state's deadline and a handler per state.
    Every transition goes through ``enter``, which reports it as a ``state`` event."""

    name = ''
    arm = ''

    def __init__(self, run: 'Pipeline', initial: Enum) -> None:
        self.run = run
        self.state = initial
        self.deadline = math.inf
        self.handlers: Dict[Enum, Callable[[Observation], None]] = {}

    def enter(self, state: Enum, now: float, budget: float) -> None:
        self.state = state
        self.deadline = now + budget
        self.run.event(now, 'state', self.name, detail=state.value)

    def move(self, state: Enum, obs: Observation, points: Points,
             start: Optional[float] = None) -> None:
        """Send this machine's arm a motion and enter ``state``, due by the motion's end (as
        the port scheduled it) plus the settle margin."""
        self.run.send(Motion(self.arm, points), start)
        self.enter(state, obs.now, self.run.motion(self.arm).end - obs.now
                   + self.run.s.settle_margin)

    def late(self, now: float) -> bool:
        return now > self.deadline

    def tick(self, obs: Observation) -> None:
        self.handlers[self.state](obs)

    def arrival(self, obs: Observation) -> Optional[bool]:
        """The arm's last motion: True once arrived, None while it may still arrive, False once
        this state's deadline has passed without it (a stalled arm)."""
        q, dq = ((obs.zu12_q, obs.zu12_dq) if self.arm == 'zu12' else
                 (obs.youbot_q, obs.youbot_dq))
        arrived = self.run.arrived(self.arm, q, obs.now, dq)
        if arrived is None and self.late(obs.now):
            return False
        return arrived

    def motion_over(self, obs: Observation, what: str) -> bool:
        """Whether the arm's last motion is over: arrived, or stalled (then reported)."""
        arrived = self.arrival(obs)
        if arrived is False:
            self.run.event(obs.now, 'arm_stalled', self.arm, detail=f'{what} not reached')
        return arrived is not None


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


def _polar(v: np.ndarray) -> Tuple[float, float]:
    return math.hypot(v[0], v[1]), math.atan2(v[1], v[0])


def _crossing(g, samples: int = 200) -> float:
    """The first fraction f in [0, 1] where g changes sign (bisected), or the end of [0, 1]
    where |g| is smaller if it does not."""
    fs = np.linspace(0.0, 1.0, samples + 1)
    gs = [g(f) for f in fs]
    for k in range(samples):
        if gs[k] == 0.0 or gs[k] * gs[k + 1] < 0.0:
            lo, hi = fs[k], fs[k + 1]
            for _ in range(30):
                mid = (lo + hi) / 2
                if g(lo) * g(mid) <= 0.0:
                    hi = mid
                else:
                    lo = mid
            return (lo + hi) / 2
    return 0.0 if abs(gs[0]) <= abs(gs[-1]) else 1.0


class Loader(Machine):
    """The Zu 12: picks materials off the running belt (meeting each where it will be, and
    moving with it while the cup is on it); a class it places itself onto its destination once
    it has ridden to the end stop, the carried ones onto the youBot's plate."""

    state: LoaderState

    name, arm = 'loader', 'zu12'

    def __init__(self, run: 'Pipeline') -> None:
        super().__init__(run, LoaderState.START)
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
        S = LoaderState
        self.handlers = {S.WAIT: self._wait, S.PICK: self._pick, S.PLACE: self._place,
                         S.RISE: self._rise, S.RETREAT: self._retreat, S.HOME: self._home,
                         S.DONE: lambda obs: None}

    def start(self, obs: Observation) -> None:
        """The first observation: the arms' poses now are their home poses."""
        self.run.home_q = {'zu12': np.array(obs.zu12_q, float),
                           'youbot': np.array(obs.youbot_q, float)}
        self.enter(LoaderState.WAIT, obs.now, self.run.s.idle_timeout)

    def _wait(self, obs: Observation) -> None:
        run, now = self.run, obs.now
        waiting = [m for m in run.materials.values() if m.status == 'seen']
        accounted = sum(1 for m in run.materials.values() if m.status != 'seen')
        if accounted >= run.layout.total or (not waiting and self.late(now)):
            why = ('every material handled' if accounted >= run.layout.total else
                   f'nothing new for {run.s.idle_timeout:.0f} s')
            run.event(now, 'loading_over', 'zu12', detail=why)
            run.event(now, 'returning', 'zu12')
            return self._move(LoaderState.HOME, obs, [Waypoint(run.home_q['zu12'].copy())])
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
        return self.run.plan('zu12', obs.zu12_q, waypoints, wait, start)

    def _from_release(self, waypoints: List[Waypoint], edge: Optional[np.ndarray] = None
                      ) -> Tuple[List[Waypoint], float]:
        """``waypoints``, after the rise from a place the cup has just let go at (see _plan),
        and how long the motion waits first."""
        if not self._at_release:
            return list(waypoints), 0.0
        rise = self.run.s.timing.place_descend
        if edge is not None:
            first = [Waypoint(known(self._above_q, 'the point above the place'), stop=False,
                              min_time=rise),
                     Waypoint(edge, stop=False)]
        else:
            first = [Waypoint(known(self._then, 'the rise from the place'), stop=not waypoints,
                              min_time=rise)]
        return first + list(waypoints), RELEASE_HOLD_S

    def _after_send(self) -> None:
        if self._at_release:
            self._at_release = False
            self._clear_at = self.run.arrival_time('zu12', known(self._clear, 'the clear point'))

    def _edge(self, a: np.ndarray, b: np.ndarray, low: float, arc: bool = False) -> np.ndarray:
        """Where the way from ``a`` (over the belt) to ``b`` (beside it) crosses the belt's near
        edge, EDGE_CLEARANCE_M outside it, and at least ``low`` above its top. The way is the
        straight line, or with ``arc`` the arc round the Zu 12's base (angle, reach and height
        changing evenly): the way its joints go, turning joint 1, when both ends lie at about
        the same reach. The straight line between two such points passes nearer the base, and
        the joints that set the reach pull in to the crossing and out again."""
        lay = self.run.layout
        y = lay.belt_y - math.copysign(lay.belt_width / 2 + EDGE_CLEARANCE_M,
                                       lay.belt_y - b[1])
        a, b = np.asarray(a, float), np.asarray(b, float)
        if arc:
            base = np.array(lay.zu12_base[:2], float)
            (ra, ta), (rb, tb) = (_polar(p[:2] - base) for p in (a, b))
            tb = ta + math.remainder(tb - ta, 2 * math.pi)
            f = _crossing(lambda f: base[1] + (ra + f * (rb - ra)) * math.sin(
                ta + f * (tb - ta)) - y)
            r, t = ra + f * (rb - ra), ta + f * (tb - ta)
            p = np.array([base[0] + r * math.cos(t), y, a[2] + f * (b[2] - a[2])])
        else:
            f = (a[1] - y) / (a[1] - b[1]) if abs(a[1] - b[1]) > 1e-9 else 0.0
            p = a + min(max(f, 0.0), 1.0) * (b - a)
        p[1], p[2] = y, max(p[2], lay.belt_top + low)
        return p

    def clear_of_the_plate(self, now: float) -> bool:
        """Whether the cup is away from the youBot's plate: not placing there, nor rising from
        it, nor swinging home (over it)."""
        return (self.state not in (LoaderState.PLACE, LoaderState.RISE, LoaderState.HOME)
                and not self._at_release and now >= self._clear_at)

    def _next(self, waiting: Sequence[Material]) -> Optional[Material]:
        """The next material to pick: the most downstream one bound for the youBot's plate (the
        youBot waits for them); one the Zu 12 places itself once the end stop holds it (it
        rides to the end)."""
        run = self.run
        ride = run.layout.end_stop
        carried = [m for m in waiting if run.layout.carried(m.color)]
        # (The youBot takes a load only while it waits at home, with room on its plate: the
        # others ride on, and queue at the end stop until it is back.)
        now_ = [m for m in carried if run.loadable(m)]
        now_ += [m for m in waiting if not run.layout.carried(m.color) and not ride]
        if not now_:
            now_ = [m for m in waiting if not run.layout.carried(m.color) and run.held(m)]
        return max(now_, key=lambda m: m.position[0], default=None)

    def _plan_pick(self, obs: Observation, m: Material, spent: float = 0.0) -> None:
        """Meet the material where it will be: the earliest contact the arm can make from
        where it is, past the pick point. One motion: to the hover point, arriving there with
        the path's velocity at its time, then down onto the material and on it while the cup
        seals, moving with it, and up to the lift height, at rest. The cup is switched on
        once the motion is sent (an armed cup seals when it touches its part).

        Real time: ``spent`` is how long earlier plans of this pick took since ``obs.now``
        (the port started them late, so they were replaced before they began)."""
        run, now, t = self.run, obs.now, self.run.s.timing
        size = m.size
        # A second attempt presses 4 mm further down.
        timing = PickTiming(**{**t.__dict__, 'contact_gap': t.contact_gap - 0.004 * m.attempts})
        track = run.track(m)
        # Real time: allow for the longest a pick's plan has taken (a motion the port starts
        # later would come too late to a moving material), after what this one has spent.
        lag = run.lag
        start = now + run.s.plan_latency + lag + spent
        t_contact = max(start + timing.descend + PICK_LEAD_S, run.reaches(m, run.s.pick_x))
        if not math.isfinite(t_contact):
            return self._leave_it(obs, m)   # it does not reach the pick point (belt off)
        seed = run.motion('zu12').goal if run.motions['zu12'] is not None else obs.zu12_q
        # The hover point moves with the contact time: a first guess from a rest-to-rest move
        # there, then later by a little until the arm makes it.
        hover = follow_pick(track, t_contact, size, timing)[0][0][1]
        q_hover = run.solve('zu12', hover, DOWN, 'world', seed)
        if q_hover is None:
            return self._pick_failed(obs, m, 'no IK solution for the pick')
        # From a place: back over the belt's edge on the way to the hover point.
        q_edge = None
        if self._at_release and self._above is not None:
            # (From the plate: round the arc, the cup clear of what rides on the belt.)
            edge = (self._edge(hover, self._above, size + EDGE_CLEARANCE_M, arc=True)
                    if self._onto_plate else self._edge(hover, self._above, EDGE_CLEARANCE_M))
            q_edge = run.solve('zu12', edge, DOWN, 'world', self._above_q)
        # (A first guess: the way to the hover point, at rest there; a plan that cannot make
        # it says by how much.)
        way, wait = self._from_release([Waypoint(q_hover)], q_edge)
        reach = wait + plan(obs.zu12_q, way, run.limits('zu12')).end
        t_contact = max(t_contact, start + reach + timing.descend)
        for _ in range(PICK_TRIES):
            if track(t_contact)[0] < run.s.pick_x - 1e-6:
                t_contact = run.reaches(m, run.s.pick_x)
            if track(t_contact + timing.dwell)[0] > (run.layout.belt_end_x - m.size / 2
                                                     + 1e-6):
                return self._leave_it(obs, m)      # off the end (no stop) before the cup is on it
            path, lift = follow_pick(track, t_contact, size, timing, SAMPLE_PERIOD_S)
            self._lift = np.asarray(lift, float)
            qs = run.solve_path('zu12', [p for _, p in path] + [lift], q_hover)
            if qs is None:
                return self._pick_failed(obs, m, 'no IK solution for the pick path')
            times = np.array([t for t, _ in path])
            q_path = np.array(qs[:-1])
            v = np.gradient(q_path, times, axis=0, edge_order=2)
            a = np.gradient(v, times, axis=0, edge_order=2)
            # To the hover point at its time, with the path's velocity; along the path (sent as
            # it is); then up to the lift point, at rest, as fast as the joints allow.
            waypoints = [Waypoint(q_path[0], velocity=v[0], acceleration=a[0], at=times[0])]
            waypoints += [Waypoint(q, velocity=vk, acceleration=ak, at=tk, direct=True)
                          for q, vk, ak, tk in zip(q_path[1:], v[1:], a[1:], times[1:])]
            waypoints.append(Waypoint(qs[-1], min_time=timing.lift))
            try:
                points = self._plan(obs, waypoints, start, q_edge)
                break
            except TooLate as too_late:
                t_contact += max(too_late.by, 0.0) + PICK_LEAD_S / 2
            except PlanError as exc:
                return self._pick_failed(obs, m, f'no motion for the pick: {exc}')
        else:
            return self._pick_failed(obs, m, 'the arm cannot meet the material in time')
        # On to the place in the same motion, through the lift point without stopping there:
        # the swing starts during the lift, and the place does not wait for an arrival check
        # at the lift point and a plan after it. (A missed grasp stops the arm at the lift
        # point instead: see _pick.)
        self._ahead = None
        place_way = self._place_way(m, self._lift, obs.youbot_pose, qs[-1])
        if not isinstance(place_way, str):
            # Lifted out of a queue (at the end stop), it comes to rest at the lift point,
            # clear of its neighbours' tops, before it swings: a swing begun during the lift
            # dragged a purple into the green queued behind it (the arm stalled, the purple fell
            # back onto the belt).
            crowded = run.crowded(m, t_contact)
            through = waypoints[:-1] + [Waypoint(qs[-1], stop=crowded, min_time=timing.lift)]
            try:
                whole = self._plan(obs, through + place_way.waypoints, start, q_edge)
            except PlanError:
                whole = None            # (the place is planned at the lift point then)
            if whole is not None:
                self._ahead = Ahead(place_way, qs[-1], points[-1][0])
                points = whole
        self.current, m.status = m, 'picking'
        self.move(LoaderState.PICK, obs, points, start=start)
        late = run.motion('zu12').start - start
        if late > 1e-9:
            # The port started it later than planned: it would miss the material. This plan
            # took as long as was allowed for it and then ``late``; plan again at once, allowing
            # for that much after this one (the new motion replaces it before it starts).
            took = lag + late
            run.lag = max(run.lag, PLAN_MARGIN * took)
            run.event(now, 'replanned', 'zu12', m, f'the pick would start {late:.2f} s late')
            if self._replans < MAX_REPLANS:
                self._replans += 1
                return self._plan_pick(obs, m, spent + took)
            # Still late: hold the arm where it is (replacing the late motion before it
            # starts) and plan afresh on the next observation.
            self._replans = 0
            hold = obs.zu12_q.copy()
            run.send(Motion('zu12', [(run.now + run.s.plan_latency, hold, np.zeros_like(hold),
                                      np.zeros_like(hold))]))
            return self._leave_it(obs, m)
        self._replans = 0
        # The cup is switched on (an armed cup seals on what it touches) now, or from a place
        # once it has risen from there: switched on where it let go, it would take the same
        # material again.
        self._arm_pending = self._at_release
        if not self._arm_pending:
            ok, why = run.ports.grip('zu12', True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        self._after_send()
        self._leave = t_contact + timing.dwell + late
        if self._ahead is not None:
            self._ahead.lift_end += late
        m.attempts += 1
        run.count_grasp('zu12')
        held = ' (held at the stop)' if run.held(m) else ''
        run.event(now, 'tracking', 'zu12', m,
                  f'contact at {t_contact:.2f} s, x {track(t_contact)[0]:.3f}{held}')

    def _leave_it(self, obs: Observation, m: Material) -> None:
        """The material cannot be picked before it leaves the belt."""
        m.status = 'seen'
        self.current = None
        self._ahead = None
        if self.state is not LoaderState.WAIT:
            self.enter(LoaderState.WAIT, obs.now, self.run.s.idle_timeout)

    def _pick_failed(self, obs: Observation, m: Material, why: str) -> None:
        run = self.run
        run.fail(obs.now, m, 'grasp_failed', why, 'zu12')
        m.slot = m.place = -1           # (a place kept for it is free again)
        self.current = None
        self._ahead = None
        self._move(LoaderState.RETREAT, obs, [Waypoint(run.home_q['zu12'].copy())])

    def _pick(self, obs: Observation) -> None:
        run, m, now = self.run, known(self.current, 'the material'), obs.now
        if self._arm_pending:
            if now < self._clear_at:
                return
            self._arm_pending = False
            ok, why = run.ports.grip('zu12', True)
            if not ok:
                return self._pick_failed(obs, m, f'the suction did not switch on: {why}')
        if not m.picked and now >= self._leave and obs.zu12_holding:
            # Off the belt from here: what the belt queued behind it moves on.
            run.off_belt(m, now)
            run.count_grasp('zu12', success=True)
            run.event(now, 'picked', 'zu12', m, f'attempt {m.attempts}')
            if self._ahead is not None:        # on its way to the place already
                self._adopt(self._ahead.way)
                self._ahead = None
                return self.enter(LoaderState.PLACE, now, run.motion('zu12').end - now
                                  + run.s.settle_margin)
        elif not m.picked and now >= self._leave and self._ahead is not None:
            # Not held after the dwell: the motion ends at the lift point instead, at rest,
            # where a missed grasp is judged.
            ahead, self._ahead = self._ahead, None
            points = run.motion('zu12').points
            q_now = min(points, key=lambda p: abs(p[0] - now))[1]
            after = [p for p in points if p[0] > now + run.s.plan_latency]
            if float(np.max(np.abs(obs.zu12_q - q_now))) > FOLLOW_TOLERANCE or not after:
                self.deadline = ahead.lift_end + run.s.settle_margin
            else:
                # From where the motion has the arm at its next sample, moving, to rest at the
                # lift point: the motion's own samples until then, and the stop from there.
                t1, q1, v1, a1 = after[0]
                stop = plan(q1, [Waypoint(ahead.q_lift)], run.limits('zu12'), t1, v0=v1, a0=a1)
                run.send_continuing('zu12', now, t1, stop.points())
                self.deadline = run.motion('zu12').end + run.s.settle_margin
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if not arrived:
            run.ports.grip('zu12', False)
            if m.picked:
                return self._place_failed(obs, m, 'the arm did not reach the lift point')
            # (Real time: the simulator took the motion in too late and refused it.) The
            # material rides on, untouched: another attempt, like a missed grasp.
            run.event(now, 'arm_stalled', 'zu12', m, f'pick attempt {m.attempts} not completed')
            if m.attempts <= run.s.max_retries:
                return self._plan_pick(obs, m)
            return self._pick_failed(obs, m, 'the arm did not reach the material')
        if not obs.zu12_holding:
            run.ports.grip('zu12', False)
            if m.picked:
                return self._place_failed(obs, m, 'dropped while lifting it')
            run.event(now, 'grasp_missed', 'zu12', m, f'attempt {m.attempts}')
            if m.attempts <= run.s.max_retries:
                return self._plan_pick(obs, m)
            return self._pick_failed(obs, m, f'not held after {m.attempts} attempts')
        if not m.picked:                     # (held, but only sealed after the lift began)
            run.off_belt(m, now)
            run.count_grasp('zu12', success=True)
            run.event(now, 'picked', 'zu12', m, f'attempt {m.attempts}')
        self._plan_place(obs, m)

    def _plan_place(self, obs: Observation, m: Material) -> None:
        """From the lift point over to above the place and down until the material is just
        above it, in one motion; the release and the rise follow once the arm is there. (A
        pick's motion goes on to the place by itself: this is for a material held only once the
        arm was at the lift point.)"""
        way = self._place_way(m, self._lift, obs.youbot_pose, self.run.motion('zu12').goal)
        if isinstance(way, str):
            return self._place_failed(obs, m, way)
        self._adopt(way)
        self.move(LoaderState.PLACE, obs, self.run.plan('zu12', obs.zu12_q, way.waypoints))

    def _place_way(self, m: Material, lift: Optional[np.ndarray], youbot_pose: Pose2D,
                   seed: np.ndarray) -> Union['PlaceWay', str]:
        """The way from the lift point ``lift`` (x, y, z; None: from above the place) onto
        ``m``'s place, or why there is none: over the belt's edge, to ``place_height`` above
        the place, and straight down until the material is just above it."""
        run, size, lay = self.run, m.size, self.run.layout
        onto_plate = lay.carried(m.color)
        if not onto_plate:
            region = lay.region_of(m.color)
            free = run.free_places(region.name, m)
            if not free:
                return f'{region.name} is full (its {len(region.slots)} slots are taken)'
            m.place = free[0]
            target = region.slots[m.place]
        else:
            free = run.plate_slots(m)
            if not free:
                return 'the youBot plate is full'
            m.slot = free[0]
            target = slot_in_world(youbot_pose, PLATE_SLOTS_IN_BASE_M[m.slot],
                                   run.layout.youbot_base_z, size)
        t = run.s.timing
        release = np.asarray(target, float) + np.array([0.0, 0.0, size + t.place_gap])
        above = release + np.array([0.0, 0.0, t.place_height])
        # Where the cup rises to over the place when it goes home or waits: clear of the belt
        # (a joint-space move straight from there to a place lower than the belt would sweep
        # the held material through the belt's side).
        transfer = release.copy()
        transfer[2] = max(above[2], run.layout.belt_top + 2 * size + t.lift_height)
        # Over the belt's near edge (rather than up to the carry height over the place and down
        # again), what the cup holds 5 cm over what can ride on the belt: onto the plate round
        # the arc (the way crosses the edge near the plate; before that it lies over the
        # belt), onto the ground target on the straight line, 5 cm over the belt's top.
        edge = (transfer if lift is None else
                self._edge(lift, above, 2 * size + EDGE_CLEARANCE_M, arc=True) if onto_plate
                else self._edge(lift, above, size + EDGE_CLEARANCE_M))
        qs = run.solve_path('zu12', [transfer, above, release, edge], seed)
        if qs is None:
            return 'no IK solution for the place path'
        q_transfer, q_above, q_release, q_edge = qs
        return PlaceWay([Waypoint(q_edge, stop=False), Waypoint(q_above, stop=False),
                         Waypoint(q_release, hold=SETTLE_S, min_time=t.place_descend)],
                        q_transfer, above, q_above, onto_plate)

    def _adopt(self, way: 'PlaceWay') -> None:
        """The place the arm is on its way to: where the cup rises from it to."""
        self._then = way.then
        self._above, self._above_q, self._onto_plate = way.above, way.above_q, way.onto_plate

    def _place_failed(self, obs: Observation, m: Material, why: str) -> None:
        self.run.ports.grip('zu12', False)
        self._pick_failed(obs, m, why)

    def _place(self, obs: Observation) -> None:
        run, m, now = self.run, known(self.current, 'the material'), obs.now
        if not obs.zu12_holding:
            return self._place_failed(obs, m, 'dropped on the way to its place')
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if not arrived:
            return self._place_failed(obs, m, 'the arm did not reach the place')
        ok, why = run.ports.grip('zu12', False)
        if not ok:
            return self._place_failed(obs, m, f'release failed: {why}')
        if not run.layout.carried(m.color):
            m.status = 'placed'
            run.event(now, 'placed', 'zu12', m, f'{run.layout.destination(m.color)} slot '
                                                 f'{m.place}')
        else:
            m.status = 'on_plate'
            run.loaded += 1
            run.event(now, 'loaded', 'zu12', m, f'plate slot {m.slot}')
        # The cup stays still while the vacuum lets go, then rises: as the start of the next
        # motion, planned now.
        self.current, self._at_release = None, True
        self.enter(LoaderState.WAIT, now, run.s.idle_timeout)
        self._wait(obs)

    def _rise(self, obs: Observation) -> None:
        if self.motion_over(obs, 'the rise from the place'):
            self.enter(LoaderState.WAIT, obs.now, self.run.s.idle_timeout)

    def _retreat(self, obs: Observation) -> None:
        if self.motion_over(obs, 'retreat'):
            self.enter(LoaderState.WAIT, obs.now, self.run.s.idle_timeout)

    def _home(self, obs: Observation) -> None:
        if self.motion_over(obs, 'home'):
            self.enter(LoaderState.DONE, obs.now, math.inf)


@dataclass
class UnloadPath:
    """The youBot's joint positions for one unload, all at one tool tilt."""
    hover: np.ndarray             # over the material on the plate
    contact: np.ndarray           # the fingers round it
    lift: List[np.ndarray]        # up off the plate, straight, to clear of its neighbours
    over: np.ndarray              # 5 cm above its drop
    drop: np.ndarray              # where it is let go
    place: int = -1               # the destination's slot it is set down on (not the pool)


# A youBot unload whose drop is reached at another tool tilt than its grip rises this much more
# before the wrist turns [m].
TILT_CHANGE_RISE_M = 0.06
# The youBot's lift off the plate: heights over the grip [m], the last clear of the neighbours.
UNLOAD_LIFT_STEPS_M = (0.01, 0.02, 0.03, 0.04, 0.05, 0.06)
# The speeds at its top tried for a lift that goes on to the drop, as fractions of its own top
# speed: the one whose whole motion ends soonest within the joints' limits is kept.
UNLOAD_LIFT_END_SPEEDS = (0.0, 0.25, 0.5, 0.75, 1.0)


class Transport(Machine):
    """The youBot: waits for its load, drives along Bezier paths with a PD follower, unloads
    one material at a time (into the pool over its wall, onto another destination's free
    slot), drives home."""

    state: TransportState

    name, arm = 'transport', 'youbot'

    def __init__(self, run: 'Pipeline') -> None:
        super().__init__(run, TransportState.WAIT_LOAD)
        self.queue: List[Material] = []              # still to unload, the current one first
        self._follower: Optional[PathFollower] = None   # while the base drives
        self._followed = False                           # the port runs the follower
        self._drive_goal = ''
        self._carry: Optional[UnloadPath] = None     # the unload's joint positions
        self._armed = False
        self._dropped: Dict[str, Set[int]] = {}        # pool drop spots used, per stand
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
        run, follower = self.run, known(self._follower, 'the path follower')
        status = follower.update(obs.now, obs.youbot_pose, obs.youbot_velocity[:2],
                                 obs.youbot_velocity[2])
        if not self._followed:
            run.ports.drive(*status.command)
        if not (status.finished or obs.now > self._drive_deadline):
            return
        self._follower = None
        run.ports.follow(None)
        run.ports.drive(0.0, 0.0, 0.0)
        if not status.finished:
            run.event(obs.now, 'drive_stalled', 'youbot', detail=(
                f'{status.position_error * 1000:.0f} mm from {self._drive_goal}'))
        run.event(obs.now, 'arrived', 'youbot', detail=self._drive_goal)

    def dropped(self, stand: str) -> Set[int]:
        """The stand's pool drop spots used so far."""
        return self._dropped.get(stand, set())

    @property
    def loading(self) -> bool:
        """Whether the youBot waits at home for its load (the Zu 12 may load its plate)."""
        return self.state is TransportState.WAIT_LOAD and not self.driving

    def _load_complete(self, on_plate: Sequence[Material]) -> bool:
        """Whether this trip's load is on the plate: every carried material the batch brings
        (or the Zu 12 is done); or the plate has no room for the next one waiting on the belt
        (it goes on the next trip). It waits while a carried material on its way could still
        have a place."""
        run = self.run
        if run.loader.state is LoaderState.DONE:
            return True
        if any(m.status == 'picking' and run.layout.carried(m.color)
               for m in run.materials.values()):
            return False
        waiting = [m for m in run.materials.values()
                   if m.status == 'seen' and run.layout.carried(m.color)]
        if any(run.plate_slots(m) for m in waiting):
            return False
        if waiting:
            return bool(on_plate)           # (full for what waits: off to make room)
        coming = [c for c in run.layout.manifest if run.layout.carried(c) and run.to_come(c)]
        return bool(on_plate) and not any(
            run.layout.free_slots(c, run.plate_taken(), run.to_come_counts()) for c in coming)

    def _wait_load(self, obs: Observation) -> None:
        run = self.run
        on_plate = [m for m in run.materials.values() if m.status == 'on_plate']
        if not self._load_complete(on_plate) or not run.loader.clear_of_the_plate(obs.now):
            return      # (nor while the Zu 12's cup is over the plate, or swinging home from it)
        order = [st.name for st in run.layout.stands]
        self.queue = sorted(on_plate, key=lambda m: (
            order.index(self._stand_for(m)), run.layout.destination(m.color) != POOL, m.slot))
        if not self.queue:
            self.enter(TransportState.DONE, obs.now, math.inf)
            return
        self.trips += 1
        run.event(obs.now, 'departing', 'youbot',
                  detail=f'{len(self.queue)} materials, trip {self.trips}')
        # The arm rises to its carry pose while the base drives: folded, it reaches down in
        # front of the base, and its fingers would scrape the floor as the base pitches.
        self._drive_to(obs, self._stand_for(self.queue[0]))

    def _stand_for(self, m: Material) -> str:
        return self.run.layout.stand_for(m.color, m.slot).name

    def _drive_to(self, obs: Observation, goal: str) -> None:
        run, lay = self.run, self.run.layout
        target = lay.youbot_home if goal == 'home' else lay.stand(goal).pose
        x, y, yaw = (float(v) for v in obs.youbot_pose)
        start = (x, y, yaw)
        via: Sequence = ()
        if goal == 'home':
            via = lay.via_back
        elif self._drive_goal in ('', 'home'):
            via = lay.via_out
        elif self._drive_goal != goal:
            via = lay.via_turn
        path = BezierPath(key_poses_between(start, target, via))
        # Mecanum: the heading turns on its own profile in time while the base travels the
        # path, both over the same time (a short path with a large turn takes the turn's).
        self._follower = PathFollower(
            path, obs.now, run.s.drive_speed, run.s.drive_accel,
            PDGains(max_speed=run.s.base_max_speed, max_turn=run.s.base_max_turn),
            turn=TurnLimits(run.s.drive_turn, run.s.drive_turn_accel))
        self._followed = run.ports.follow(self._follower)
        self._drive_goal = goal
        run.event(obs.now, 'driving', 'youbot', detail=f'to {goal}, {path.length:.2f} m')
        budget = self._follower.profile.duration + run.s.drive_margin
        self._drive_deadline = obs.now + budget
        self.enter(TransportState.DRIVE, obs.now, budget)
        if goal != 'home' and self.queue:
            self._ready_arm(obs, lay.stand(goal).pose)

    def _drive(self, obs: Observation) -> None:
        run = self.run
        if self._drive_goal == 'home':
            if self.driving:
                return
            # Back to its start pose only at home, from the carry pose (a folded arm reaches
            # down in front of the base, and its fingers would catch the floor as the base
            # pitches). The cell's youBot starts in the carry pose: nothing is left to do.
            if not self.motion_over(obs, 'carry pose'):
                return
            if run.carried_to_come() and run.loader.state is not LoaderState.DONE:
                # More to carry: it waits here, the arm in its carry pose, for the next load.
                run.event(obs.now, 'waiting_for_load', 'youbot',
                          detail=f'{run.carried_to_come()} carried materials to come')
                return self.enter(TransportState.WAIT_LOAD, obs.now, math.inf)
            run.plan_home('youbot', obs)
            return self.enter(TransportState.FOLD, obs.now, run.motion('youbot').end
                              - obs.now + run.s.settle_margin)
        # Here only when the arm could not be sent down onto the first material it unloads
        # here (_ready_arm): from the carry pose, the unload is planned (or its failure told).
        if self.queue and not self.motion_over(obs, 'carry pose'):
            return
        if self.queue or not self.driving:
            self._next_unload(obs)

    def _next_unload(self, obs: Observation) -> None:
        run = self.run
        if not self.queue:
            # Home: the arm rises from the drop (its fingers 4 cm over the pool's wall) to the
            # upright carry pose as the base sets off (slowly: in the first 0.3 s it moves 3 cm,
            # the fingers rise further).
            run.send(Motion('youbot', run.plan('youbot', obs.youbot_q,
                                               [Waypoint(YOUBOT_CARRY_Q.copy())])))
            return self._drive_to(obs, 'home')
        m = self.queue[0]
        if self._stand_for(m) != self._drive_goal:
            return self._drive_to(obs, self._stand_for(m))
        self._plan_unload(obs, m)

    def _ready_arm(self, obs: Observation, stand: Pose2D) -> None:
        """While the base drives to a stand: the arm up through the carry pose (folded, it
        reaches down in front of the base, and its fingers would scrape the floor as the base
        pitches), over the first material it unloads there, and on down onto it without
        stopping over it: the grasp starts as the arm arrives, the base still on its way or
        not. Between the stands the arm swings joint 1 round 4.1 rad, and the first grasp there
        waited for it: a stop 12 cm over the material, and the descent from there, added 0.7 s
        to that wait."""
        run, m = self.run, self.queue[0]
        path = self._unload_path(m, stand, YOUBOT_CARRY_Q, high=True)
        if path is None:
            # Up to the carry pose; the unload is planned (and its failure told) from there.
            run.send(Motion('youbot', run.plan('youbot', obs.youbot_q,
                                               [Waypoint(YOUBOT_CARRY_Q.copy())])))
            return
        self._approach(obs, m, path, [Waypoint(YOUBOT_CARRY_Q.copy(), stop=False)])

    def _unload_path(self, m: Material, pose: Pose2D, seed: np.ndarray,
                     high: bool = False) -> Optional['UnloadPath']:
        """Joint positions over the material on the plate (5 cm over it with ``high``, else 3), on
        it, up its straight lift clear of its neighbours, above its drop and at its drop, for
        the base standing at ``pose``. The fingers come down from 3 cm over its top face (the
        neighbours' tops are level with it). The material rises 6 cm, over their 5 cm, before it
        swings out, through a point every centimetre at the same tool tilt: between two points
        6 cm apart the joints' straight line swings what is held 2 cm sideways and tilts it 8
        degrees, into a neighbour 1 cm away."""
        run = self.run
        size, t = m.size, run.s.timing
        slot = PLATE_SLOTS_IN_BASE_M[m.slot]
        top = (PLATE_TOP_IN_BASE_M + size + YOUBOT_GRASP_STANDOFF_M
               - 0.004 * m.unload_attempts)
        contact = np.array([slot[0], slot[1], top])
        hover = contact + np.array([0.0, 0.0, 0.05 if high else 0.03])
        lift = [contact + np.array([0.0, 0.0, h]) for h in UNLOAD_LIFT_STEPS_M]
        stand = self._stand_for(m)
        region = run.layout.region_of(m.color)
        if not region.drop:
            # Its destination's free slots, the first the arm reaches from here.
            up = np.array([0.0, 0.0, size + t.place_gap + YOUBOT_GRASP_STANDOFF_M])
            candidates = [(k, region.slots[k] + up) for k in run.free_places(region.name, m)]
        else:
            # The stand's first unused drop; if the arm cannot reach it from this slot as the
            # base stands (a far slot, a base a centimetre off), the others in turn. A drop
            # spot is used once: a cube dropped onto another can tumble back over the wall.
            drops = run.layout.stand(stand).drops
            used = self._dropped.get(stand, set())
            candidates = [(k, d) for k, d in enumerate(drops) if k not in used]
        for place, drop_world in candidates:
            drop = world_to_base(pose, drop_world)
            drop[2] -= run.layout.youbot_base_z
            # Over the drop, at least as high as the lift's top: a swing there keeps what is
            # held over the plate's other materials where a joint motion from the lift's top
            # straight down to a pool drop (lower than the plate) would swing it into the next
            # one (campaign trial 31). Taken only when that is so (_lift).
            over = drop.copy()
            over[2] = max(drop[2] + 0.05, lift[-1][2])
            path = run.solve_tilted([hover, contact, *lift, over, drop],
                                    np.array(seed, float))
            if path is None and region.drop:
                # A drop spot further in is reached leaning another way: the material, let go
                # over the pool, need not stay level (one it is set down must). It rises
                # TILT_CHANGE_RISE_M more first, still level, so that what it holds clears the
                # others on the plate as the wrist turns.
                rise = np.array(lift[-1], float) + np.array([0.0, 0.0, TILT_CHANGE_RISE_M])
                grip = run.solve_tilted([hover, contact, *lift, rise], np.array(seed, float))
                above = np.array(over, float)
                above[2] = max(over[2], rise[2])
                out = run.solve_tilted([above, drop], grip[-1]) if grip is not None else None
                path = grip + out if grip is not None and out is not None else None
            if path is not None:
                return UnloadPath(path[0], path[1], path[2:-2], path[-2], path[-1], place)
        return None

    def _lift(self, obs: Observation, m: Material, then: Sequence[Waypoint] = (),
              detour: Sequence[Waypoint] = ()) -> Points:
        """The motion from the grip: the straight lift off the plate, timed along the line (a
        joint motion between its ends would swing the material into its neighbours), at rest
        at its top, or going on from there through ``then`` (or ``detour`` where ``then``
        would not keep ``m`` clear of the plate's other materials): at the speed, of those
        tried, that ends soonest and keeps the joints within their limits."""
        run = self.run
        limits = run.limits('youbot')
        others = self._others(m)
        carry = known(self._carry, 'the unload path')
        for way in ((then, detour) if detour else (then,)):
            best = None
            for speed in (UNLOAD_LIFT_END_SPEEDS if way else (0.0,)):
                lift = timed_path([obs.youbot_q, *carry.lift], limits,
                                  run.now + run.s.plan_latency, end_speed=speed,
                                  min_time=run.s.timing.lift)
                try:
                    points = run.plan('youbot', obs.youbot_q, [*lift, *way])
                except PlanError:
                    continue
                within = all(np.all(np.abs(v) <= limits.velocity) for _, _, v, _ in points)
                if (within and (best is None or points[-1][0] < best[-1][0])
                        and clear_of_the_plate(points, others, m.size)):
                    best = points
            if best is not None:
                return best
        raise PlanError('no motion off the plate within the joint limits and clear of the '
                        'other materials')

    def _others(self, m: Material) -> List[Tuple[float, float]]:
        """The plate slots of the materials on the plate but ``m``."""
        return [PLATE_SLOTS_IN_BASE_M[o.slot] for o in self.run.materials.values()
                if o.status == 'on_plate' and o.slot >= 0 and o.id != m.id]

    def _stand_pose(self, obs: Observation) -> Pose2D:
        """Where the base stands for its unloads: its drive's goal while it is on its way."""
        if self.driving:
            return self.run.layout.stand(self._drive_goal).pose
        return obs.youbot_pose

    def _plan_unload(self, obs: Observation, m: Material) -> None:
        """Down onto the material on the plate; the gripper closes once the arm is there."""
        run, now = self.run, obs.now
        plan = self._unload_path(m, self._stand_pose(obs), obs.youbot_q)
        if plan is None:
            self.queue.pop(0)
            run.fail(now, m, 'grasp_failed', 'unload: no IK solution', 'youbot')
            return self._next_unload(obs)
        self._approach(obs, m, plan)

    def _approach(self, obs: Observation, m: Material, plan: 'UnloadPath',
                  through: Sequence[Waypoint] = ()) -> None:
        """Down onto ``m`` on the plate through ``through`` and its hover; the gripper closes
        once the arm is there (GRASP)."""
        run, t = self.run, self.run.s.timing
        self._carry, self._armed = plan, False
        m.place = plan.place                # (kept for it: the pool's drops are the stand's)
        m.unload_attempts += 1
        run.count_grasp('youbot')
        self.move(TransportState.GRASP, obs, run.plan('youbot', obs.youbot_q, [
            *through, Waypoint(plan.hover, stop=False),
            Waypoint(plan.contact, hold=SETTLE_S, min_time=t.descend)]))

    def _grasp(self, obs: Observation) -> None:
        run, m, now = self.run, self.queue[0], obs.now
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if not arrived:
            return self._unload_failed(obs, m, 'grasp_failed',
                                       'unload: the arm did not reach the material')
        if not self._armed:
            # Closed only now: its 20 mm reach would take a neighbour on the way down.
            run.ports.grip('youbot', True)
            self._armed = True
            return
        if not obs.youbot_armed:
            if self.late(now):
                return self._unload_failed(obs, m, 'grasp_failed',
                                           'unload: the gripper does not report closing')
            return                      # (the grip state from before the gripper closed)
        if not obs.youbot_holding:
            run.ports.grip('youbot', False)
            run.event(now, 'grasp_missed', 'youbot', m, f'attempt {m.unload_attempts}')
            if m.unload_attempts <= run.s.max_retries:
                return self._plan_unload(obs, m)
            return self._unload_failed(obs, m, 'grasp_failed', f'unload: not held after '
                                       f'{m.unload_attempts} attempts')
        run.count_grasp('youbot', success=True)
        run.event(now, 'unload_grasped', 'youbot', m, f'attempt {m.unload_attempts}')
        if self.driving:
            # Up clear of its neighbours, and held there until the base stands.
            self._drop_pending = True
            try:
                return self.move(TransportState.CARRY, obs, self._lift(obs, m))
            except PlanError as exc:
                return self._unload_failed(obs, m, 'failed', f'unload: {exc}')
        self._carry_out(obs, m, known(self._carry, 'the unload path').over,
                            known(self._carry, 'the unload path').drop, lift=True)

    def _carry_out(self, obs: Observation, m: Material, over: np.ndarray, drop: np.ndarray,
                   lift: bool = False) -> None:
        """Over to the material's drop (first up off the plate with ``lift``)."""
        run, t = self.run, self.run.s.timing
        self._drop_pending = False
        if not run.layout.region_of(m.color).drop:
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
                points = run.plan('youbot', obs.youbot_q, carry)
                if not clear_of_the_plate(points, self._others(m), m.size):
                    points = run.plan('youbot', obs.youbot_q, detour)
        except PlanError as exc:
            return self._unload_failed(obs, m, 'failed', f'unload: {exc}')
        self.move(TransportState.CARRY, obs, points)

    def _unload_failed(self, obs: Observation, m: Material, kind: str, why: str) -> None:
        self._drop_pending = False
        self.run.ports.grip('youbot', False)
        self.queue.pop(0)
        self.run.fail(obs.now, m, kind, why, 'youbot')
        self._next_unload(obs)

    def _carry_to_drop(self, obs: Observation) -> None:
        run, m, now = self.run, self.queue[0], obs.now
        if not obs.youbot_holding:
            return self._unload_failed(obs, m, 'failed', 'unload: dropped on the way')
        arrived = self.arrival(obs)
        if arrived is None:
            return
        if self._drop_pending:
            if self.driving:
                return              # (held up over the plate until the base stands)
            if not arrived:
                run.event(now, 'arm_stalled', 'youbot', m, 'the lift off the plate not completed')
            # Over to its drop as the base stands now (the drive ends a little off its goal).
            path = (self._unload_path(m, obs.youbot_pose, obs.youbot_q)
                    or known(self._carry, 'the unload path'))
            self._carry, m.place = path, path.place
            return self._carry_out(obs, m, path.over, path.drop)
        if not arrived:
            run.event(now, 'arm_stalled', 'youbot', m, 'unload motion not completed')
        run.ports.grip('youbot', False)
        m.status = 'delivered'
        where = run.layout.destination(m.color)
        if run.layout.region_of(m.color).drop:
            self._dropped.setdefault(self._drive_goal, set()).add(m.place)
            where += f' drop {m.place} from {self._drive_goal}'
        else:
            where += f' slot {m.place}'
        run.event(now, 'delivered', 'youbot', m, where)
        # The arm stays still while the material falls free of the fingers.
        self.enter(TransportState.RELEASE, now, RELEASE_HOLD_S)

    def _release(self, obs: Observation) -> None:
        if self.late(obs.now):
            self.queue.pop(0)
            self._next_unload(obs)

    def _fold(self, obs: Observation) -> None:
        if self.motion_over(obs, 'home pose'):
            self.enter(TransportState.DONE, obs.now, math.inf)


class Pipeline:
    """The whole run: the two machines and what they share (materials, belt, arm motions,
    events, the ports). Call ``tick(observation)`` every control period until ``finished``."""

    def __init__(self, layout: CellLayout, ports: Ports, settings: Settings = Settings(),
                 start_time: float = 0.0, belt_ran_before: bool = False) -> None:
        """``belt_ran_before``: the belt was already running at the layout's speed when the
        run started (a real-time simulator started with its belt on, the coordinator later):
        what a frame showed before the start has ridden on since."""
        self.layout, self.ports, self.s = layout, ports, settings
        self.start_time = start_time
        self.events: List[Event] = []
        self.materials: Dict[int, Material] = {}
        self.result: Optional[RunResult] = None
        self.grasps = {'zu12': [0, 0], 'youbot': [0, 0]}     # attempts, successes
        self.loaded = 0
        self.motions: Dict[str, Optional[Motion]] = {'zu12': None, 'youbot': None}
        self.belt_running = False
        self.belt_log: List[Tuple[float, bool]] = [
            (-math.inf, True) if belt_ran_before else (start_time, False)]
        self._belt_time = start_time      # the belt model's time (``_advance_belt``)
        self.lag = 0.0                    # the longest a pick's plan has taken (real time) [s]
        self.belt_stops = 0               # the belt stopped while loading (its queue full)
        self.now = start_time
        self.q_now = np.zeros(0)
        self.home_q: Dict[str, np.ndarray] = {}
        self.loader = Loader(self)
        self.transport = Transport(self)

    # --- the loop -----------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        return self.result is not None

    @property
    def loader_state(self) -> LoaderState:
        return self.loader.state

    @property
    def transport_state(self) -> TransportState:
        return self.transport.state

    def tick(self, obs: Observation) -> None:
        if self.finished:
            return
        self.now, self.q_now = obs.now, obs.zu12_q
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

    @property
    def grasp_attempts(self) -> int:
        return sum(a for a, _ in self.grasps.values())

    @property
    def grasp_successes(self) -> int:
        return sum(s for _, s in self.grasps.values())

    # --- what the machines share --------------------------------------------------------------
    def count_grasp(self, arm: str, success: bool = False) -> None:
        self.grasps[arm][1 if success else 0] += 1

    def event(self, now: float, kind: str, robot: str = '', m: Optional[Material] = None,
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

    def fail(self, now: float, m: Material, kind: str, why: str, robot: str) -> None:
        m.status, m.failure = ('missed' if kind == 'missed' else 'failed'), why
        self.event(now, kind, robot, m, why)

    def plan_home(self, arm: str, obs: Observation, ready: bool = False) -> None:
        q = obs.zu12_q if arm == 'zu12' else obs.youbot_q
        self.send(Motion(arm, self.plan(arm, q, [Waypoint(self.home_q[arm].copy())])))
        if not ready:
            self.event(obs.now, 'returning', arm)

    def to_come(self, name: str) -> int:
        """Materials of class ``name`` the batch still brings that are not on the plate yet,
        nor placed, delivered or given up (nor being picked for a plate slot kept for it)."""
        gone = sum(1 for m in self.materials.values() if m.color == name and (
            m.status in ('on_plate', 'placed', 'delivered', 'failed', 'missed')
            or (m.status == 'picking' and m.slot >= 0)))
        return max(0, self.layout.manifest.get(name, 0) - gone)

    def to_come_counts(self) -> Dict[str, int]:
        return {c: self.to_come(c) for c in self.layout.manifest}

    def carried_to_come(self) -> int:
        """Carried materials the youBot has still to take (not on its plate yet)."""
        return sum(self.to_come(c) for c in self.layout.manifest if self.layout.carried(c))

    def plate_taken(self, but: Optional[Material] = None) -> Dict[int, str]:
        """The plate's slots that a material is on, or kept for one being picked."""
        return {x.slot: x.color for x in self.materials.values()
                if x.slot >= 0 and x is not but and x.status in ('picking', 'on_plate')}

    def plate_slots(self, m: Material) -> List[int]:
        """The plate slots free for ``m`` now, in the order they are filled: for a pool
        material, only in a row whose stand has a drop spot left for it."""
        taken = self.plate_taken(m)
        free = self.layout.free_slots(m.color, taken, self.to_come_counts())
        if not self.layout.region_of(m.color).drop:
            return free
        room = {}
        for st in self.layout.stands:
            bound = sum(1 for k, c in taken.items() if slot_row(k) == st.row
                        and self.layout.region_of(c).drop)
            room[st.row] = len(st.drops) - len(self.transport.dropped(st.name)) - bound
        return [k for k in free if room.get(slot_row(k), 0) > 0]

    def loadable(self, m: Material) -> bool:
        """Whether the Zu 12 may put ``m`` onto the youBot's plate now: it waits at home, and
        has a slot for it."""
        return self.transport.loading and bool(self.plate_slots(m))

    def free_places(self, region: str, m: Material) -> List[int]:
        """The slots of a destination (its Region's, in order) that no other material has or
        is kept for: a material never goes down on another."""
        taken = {x.place for x in self.materials.values()
                 if x is not m and x.place >= 0 and x.status not in ('failed', 'missed')
                 and self.layout.destination(x.color) == region}
        slots = self.layout.regions[region].slots
        return [k for k in range(len(slots)) if k not in taken]

    # --- the belt -----------------------------------------------------------------------------
    def _on_belt(self) -> List[Material]:
        """The materials the belt carries (or its stop holds), as the coordinator believes:
        those a failed pick left there too (they ride on, and queue at the stop)."""
        return [m for m in self.materials.values()
                if m.status in ('seen', 'picking', 'failed') and not m.picked]

    def _items(self, mats: Sequence[Material]) -> List[Item]:
        # Along the belt as world x (the belt runs along +x; only differences matter).
        return [Item(m.position[0], m.position[1] - self.layout.belt_y, m.size, m.size)
                for m in mats]

    @property
    def _stop(self) -> float:
        """The stop's face (world x; infinity without one)."""
        return self.layout.belt_end_x if self.layout.end_stop else math.inf

    def held(self, m: Material) -> bool:
        """Whether the end stop (or what it holds) holds the material now."""
        mats = self._on_belt()
        return m in mats and held(self._items(mats), self._stop)[mats.index(m)]

    def track(self, m: Material) -> Callable[[float], np.ndarray]:
        """Where the material's centre will be at a time, while the belt runs as it does now:
        carried on, and held once it reaches the stop or what the stop holds."""
        mats = self._on_belt()
        items, k, now = self._items(mats), mats.index(m), self.now
        speed = self.layout.belt_speed if self.belt_running else 0.0
        y, z = float(m.position[1]), float(m.position[2])

        def at(t: float) -> np.ndarray:
            return np.array([advance(items, self._stop, speed * max(0.0, t - now))[k], y, z])
        return at

    def reaches(self, m: Material, x: float) -> float:
        """When the material's centre reaches ``x`` (now if it is there already; infinity if it
        never will: the belt is stopped, or the stop holds it upstream of ``x``)."""
        if x > self.layout.belt_end_x - m.size / 2:
            return math.inf                         # beyond the belt's end
        if m.position[0] >= x:
            return self.now
        speed = self.layout.belt_speed if self.belt_running else 0.0
        if speed <= 0.0 or self.held(m):
            return math.inf
        t = self.now + (x - m.position[0]) / speed
        return t if self.track(m)(t)[0] >= x - 1e-6 else math.inf

    def crowded(self, m: Material, t: float) -> bool:
        """Whether another material on the belt will be next to ``m`` at ``t`` (less than
        QUEUE_CLEARANCE_M between their faces along the belt, overlapping across it): a
        material lifted from there drags against it if it moves sideways before it is clear of
        its top."""
        mats = self._on_belt()
        if m not in mats:
            return False
        x = self.track(m)(t)[0]
        for o in mats:
            if o is m:
                continue
            reach = (m.size + o.size) / 2
            if (abs(self.track(o)(t)[0] - x) < reach + QUEUE_CLEARANCE_M
                    and abs(o.position[1] - m.position[1]) < reach):
                return True
        return False

    def off_belt(self, m: Material, now: float) -> None:
        """The cup has lifted the material off the belt (what queued behind it moves on)."""
        self._advance_belt(now)
        m.picked = True

    def _advance_belt(self, now: float) -> None:
        """Carry the model of the belt forward to ``now``."""
        travel = self.layout.belt_speed * self._running_time(self._belt_time, now)
        self._belt_time = max(self._belt_time, now)
        if travel <= 0.0:
            return
        mats = self._on_belt()
        for m, x in zip(mats, advance(self._items(mats), self._stop, travel)):
            m.position = np.array([x, m.position[1], m.position[2]])
            m.stamp = now

    def _belt(self, now: float, running: bool) -> None:
        if running != self.belt_running:
            effective = self.ports.belt(self.layout.belt_speed if running else 0.0)
            self._advance_belt(now)
            self.belt_running = running
            self.belt_log.append((max(now, effective or now), running))
            loading = self.loader.state not in (LoaderState.HOME, LoaderState.DONE)
            if not running and loading:
                self.belt_stops += 1            # (stopped for the queue, not at the end)
            self.event(now, 'belt_started' if running else 'belt_stopped',
                       detail='the queue would overflow the belt' if not running and loading
                       else '')

    def _belt_wanted(self, now: float) -> bool:
        """The belt runs at a uniform speed from the start until loading is over, unless what
        waits for the youBot would overflow it: the end stop's queue reaching back to the pick
        point, or (without a stop) a material the Zu 12 cannot take now near the belt's end."""
        if self.loader.state in (LoaderState.HOME, LoaderState.DONE):
            return False
        return not self._overflow()

    def _overflow(self) -> bool:
        mats = self._on_belt()
        if not mats:
            return False
        if self.layout.end_stop:
            flags = held(self._items(mats), self._stop)
            tail = min((m.position[0] - m.size / 2 for m, h in zip(mats, flags) if h),
                       default=math.inf)
            return tail < self.s.pick_x + QUEUE_MARGIN_M
        end = self.layout.belt_end_x - QUEUE_MARGIN_M
        return any(m.status == 'seen' and m.position[0] + m.size / 2 > end
                   and self.layout.carried(m.color) and not self.loadable(m) for m in mats)

    def _running_time(self, t0: float, t1: float) -> float:
        total = 0.0
        log = self.belt_log + [(t1, self.belt_running)]
        for (start, running), (end, _) in zip(log, log[1:]):
            if running:
                total += max(0.0, min(end, t1) - max(start, t0))
        return total

    # --- perception ---------------------------------------------------------------------------
    def _see(self, obs: Observation) -> None:
        self._advance_belt(obs.now)
        for d in obs.detections:
            m = self.materials.get(d.id)
            if m is None:
                if (d.hits < self.s.confirm_hits or not self._on_belt_area(d.position)
                        or d.position[0] >= self.s.pick_x):
                    continue
                if d.color not in self.layout.rules:
                    continue                # (no class of this cell: the vision's config)
                m = self.materials[d.id] = Material(d.id, d.color, self._seen_at(d, obs.now),
                                                    obs.now, d.hits, detection=d,
                                                    size=self.layout.size_of(d.color))
                self.event(obs.now, 'seen', 'vision', m,
                           f'at {np.round(m.position, 3).tolist()}')
            elif m.status == 'seen':
                m.position, m.stamp, m.hits = self._seen_at(d, obs.now), obs.now, d.hits
            m.last_seen = obs.now
        # Without an end stop, a material still on the belt past its end was not picked.
        for m in self.materials.values():
            if (m.status == 'seen' and not self.layout.end_stop
                    and m.position[0] > self.layout.belt_end_x):
                self.fail(obs.now, m, 'missed', 'went off the belt end unpicked', 'zu12')

    def _seen_at(self, d: Detection, now: float) -> np.ndarray:
        """A detection carried to ``now``: in the camera's view the belt carries it freely."""
        travel = self.layout.belt_speed * self._running_time(d.stamp, now)
        return np.asarray(d.position, float) + np.array([travel, 0.0, 0.0])

    def _on_belt_area(self, position: Vector) -> bool:
        """Whether a detection lies on the belt. The camera also sees beside it, and downstream
        of the pick point, where the Zu 12 lifts materials and carries them to their places: a
        material in the cup is not a new one. A new material is confirmed where it enters the
        view, upstream of the pick point (``_see``)."""
        return abs(position[1] - self.layout.belt_y) <= self.layout.belt_width / 2

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
        self.result = RunResult(
            status=status, completion_time=now - self.start_time, total=self.layout.total,
            identified=len(mats),
            picked=sum(1 for m in mats if m.picked),
            delivered=sum(1 for m in mats if m.status in ('placed', 'delivered')),
            grasp_attempts=self.grasp_attempts, grasp_successes=self.grasp_successes,
            zu12_grasp_attempts=self.grasps['zu12'][0],
            zu12_grasp_successes=self.grasps['zu12'][1],
            youbot_grasp_attempts=self.grasps['youbot'][0],
            youbot_grasp_successes=self.grasps['youbot'][1], loaded=self.loaded,
            trips=self.transport.trips, belt_stops=self.belt_stops,
            missed=sum(1 for m in mats if m.status == 'missed'),
            failed=sum(1 for m in mats if m.status == 'failed'), message=message,
            materials=[{'id': m.id, 'color': m.color, 'status': m.status,
                        'attempts': m.attempts, 'unload_attempts': m.unload_attempts,
                        'failure': m.failure} for m in mats])
        self.event(now, 'finished', detail=f'{status}{": " + message if message else ""}')

    # --- kinematics through the port ----------------------------------------------------------
    def solve(self, arm: str, position, orientation, frame: str, seed) -> Optional[np.ndarray]:
        q, why = self.ports.solve(arm, position, orientation, frame, seed)
        if q is None:
            self.event(self.now, 'ik_failed', arm,
                       detail=f'{np.round(position, 3).tolist()}: {why}')
        return q

    def solve_path(self, arm: str, positions, seed) -> Optional[List[np.ndarray]]:
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

    def solve_tilted(self, points: Sequence[np.ndarray], seed: np.ndarray
                     ) -> Optional[List[np.ndarray]]:
        """Joint positions for a youBot path whose every point has the same tool tilt: its arm
        reaches the plate's far slots only leaning outwards, and a material held at one tilt
        stays level only if it is set down at the same tilt."""
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
                return plan
        self.event(self.now, 'ik_failed', 'youbot',
                   detail=f'{np.round(points[1], 3).tolist()} via '
                          f'{np.round(points[-1], 3).tolist()} at any one tilt up to 80 deg')
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


# The youBot's arm upright (the datasheet's candle pose) while the base drives home.
YOUBOT_CARRY_Q = np.zeros(5)
# The youBot's fingertips reach 10.4 mm beyond gripper_tcp: it grasps a material's top face with
# the TCP this far above it, so that the fingertips do not push the material away.
YOUBOT_GRASP_STANDOFF_M = GRASP_STANDOFF_M


# What the youBot holds passes this far over the tops of the plate's other materials [m].
PLATE_CLEARANCE_M = 0.01
_YOUBOT_FK = YoubotKinematics('gripper_tcp')


def clear_of_the_plate(points: Points, others: Sequence[Tuple[float, float]], size: float,
                       steps: int = 8) -> bool:
    """Whether a youBot motion (samples of time, positions, velocities, accelerations) keeps
    the material it holds (gripped by its top face) ``PLATE_CLEARANCE_M`` over the materials
    in the plate slots ``others`` wherever it passes over one: along the path the controller
    follows between the samples (cubic in position and velocity)."""
    if not others:
        return True
    tops = PLATE_TOP_IN_BASE_M + size + PLATE_CLEARANCE_M
    reach = size + 0.005         # centre to centre, nearer than this in x and y: over it
    for (t0, q0, v0, _), (t1, q1, v1, _) in zip(points, points[1:]):
        h = t1 - t0
        for x in np.linspace(0.0, 1.0, steps, endpoint=False):
            q = ((2 * x**3 - 3 * x**2 + 1) * q0 + (x**3 - 2 * x**2 + x) * h * v0
                 + (-2 * x**3 + 3 * x**2) * q1 + (x**3 - x**2) * h * v1)
            px, py, pz = _YOUBOT_FK.fk(q)[:3, 3]
            bottom = pz - YOUBOT_GRASP_STANDOFF_M - size
            if bottom < tops and any(abs(px - sx) < reach and abs(py - sy) < reach
                                     for sx, sy in others):
                return False
    return True
