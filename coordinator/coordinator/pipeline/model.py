"""What the pipeline's machines work with (no ROS): the observation they see, the ports they
act through, the settings, a material and its status, an arm motion, the result."""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import (
    List,
    Mapping,
    Optional,
    Protocol,
    Sequence,
    Tuple,
    TypeVar,
)

import numpy as np

from cell_layout.pick_geometry import CELL_TIMING
from controllers.arrays import Vector
from controllers.bezier import Pose2D
from controllers.path_follower import PathFollower
from controllers.pick_place import PickTiming
from trial_record.events import Event

DOWN = (1.0, 0.0, 0.0, 0.0)                  # tool z pointing down (x, y, z, w)
# A pick's contact is planned at least this long after the arm could be over the material, and
# moved this much later while the arm cannot make it [s].
PICK_LEAD_S = 0.1
# An arm swings in over the materials already at a set-down's destination (or on the plate)
# with what it holds at least this far above the tallest of them [m].
SET_DOWN_CLEARANCE_M = 0.02
PICK_TRIES = 6
# A pick under way is re-aimed when the material will be this far (along the belt) from where
# its motion meets it, as the newest sightings and belt speed tell, and farther than twice the
# prediction's own error (the speed's standard error times how far ahead it predicts) [m] (the
# cup seals within 4 mm of a face's centre in the fake cell, the real one's within about
# 20 mm) ...
REAIM_TOLERANCE_M = 0.003
# ... up to this long before the cup is over it, about to come down; from then on the arm is in
# the camera's view above the material and hides part of it, and what the camera sees of it is
# not used (its centre seen up to 20 mm off, in the perturbed sweep) [s].
REAIM_LEAD_S = 0.6
# A pick that cannot be re-aimed, and would meet its material farther than this from the centre
# of its top face, is called off at once (the arm stopped where it is, the cup switched off):
# it would miss at the lift point otherwise, a second and a half later (the cup seals on the
# face it comes down on: half a 50 mm cube's edge, less a margin) [m].
CALL_OFF_M = 0.02
# A pick whose joint path is out of the limits is met this much later on the track [s].
PICK_REPLAN_STEP_S = 0.3
# Real time: a pick allows for this much more than the longest plan of one has taken (the next
# may need a few more IK calls).
PLAN_MARGIN = 1.25
# A pick the port starts late is planned again this many times at most.
MAX_REPLANS = 2
# A released material falls free of the cup or the fingers before the tool moves on [s]: it has
# dropped 5 cm by then, and the tool's next motion starts from rest (0.2 s cost 0.1 s a cycle).
RELEASE_HOLD_S = 0.1
# After a release, an arm that is still moving (one that sagged under a heavy load springs back
# to its reference as it lets go) is waited for, up to this long, before its next motion is
# planned from where it is: planned while it sprang back 0.11-0.16 rad, the motion's first
# point was out of the joints' speed limits when it arrived, the controller refused it and
# held still, and the next unload failed, "the arm did not reach the material" [s].
SPRING_BACK_WAIT_S = 1.0
# A motion that ends where the tool grips or lets go holds its goal this long, so that the arm
# has settled there [s]. Its arrival is judged on joint feedback as well (within
# ``arrive_tolerance`` and at rest), so the hold need only cover a control period or so
# (0.15 s cost about a second per run over the 15 grasps and releases).
SETTLE_S = 0.05
# A material on the belt with another this near (between their faces, along the belt) is lifted
# clear of it before it swings away [m].
QUEUE_CLEARANCE_M = 0.03
# A material lifted off the end stop's queue with another pressed against it (the belt drives
# the queue into the stop) drags its neighbours up by their faces' friction: 13 oranges of
# 0.38 kg rose 1 to 4 cm with the one lifted and fell back 2 cm sideways and turned 12 degrees,
# and the next place hit them. The belt pauses from this long before the cup's contact until
# the lift is over, and the queue's pressure is gone [s].
QUEUE_LIFT_PAUSE_LEAD_S = 0.5
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


@dataclass(frozen=True)
class ArmReading:
    """An arm as its sensors last told."""
    q: np.ndarray                               # joint positions
    dq: Optional[np.ndarray] = None             # measured joint velocities, if known
    holding: bool = False                       # its grip tool holds something
    armed: bool = False                         # its grip tool is switched on (as published)


@dataclass(frozen=True)
class BaseReading:
    """A mobile base as its odometry last told, in the world frame (corrected by its laser
    scans where it has a scanner)."""
    pose: Pose2D
    velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)   # world vx, vy, wz
    located: str = ''       # how its laser scans correct its odometry (none: '')


@dataclass
class Observation:
    """What the cell's sensors told at ``now``: each arm and each mobile base by its robot's
    name, and the vision's detections."""
    now: float
    arms: Mapping[str, ArmReading]
    bases: Mapping[str, BaseReading]
    detections: Sequence[Detection] = ()
    belt: Sequence[Tuple[float, float]] = ()     # the conveyor's encoder: (stamp, travel) read


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

    def drive(self, robot: str, vx: float, vy: float, wz: float) -> None:
        """A twist for mobile robot ``robot``'s base (in its base_link)."""

    def follow(self, robot: str, follower: Optional[PathFollower]) -> bool:
        """Have ``robot``'s base controller run ``follower`` on every odometry message (None:
        stop that). True if the port does so (real time: a decision held up by IK calls for the
        other arm must not leave the base running on a stale command), and the pipeline's
        ticks only judge the drive; False if the ticks send its commands (lock-step, where a
        decision sees every state)."""

    def event(self, event: Event) -> None: ...


@dataclass(frozen=True)
class Settings:
    pick_x: float = -0.6              # the loader picks materials downstream of this x [m]
    confirm_hits: int = 8             # frames a track needs before it is acted on
    max_retries: int = 1              # extra grasp attempts on a missed grasp
    loader_scaling: float = 1.0       # fraction of the loader arm's joint speed limits
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
    # gentle enough that the cup and the fingers do not knock it (the layout checks the
    # loader's reach with the same).
    timing: PickTiming = CELL_TIMING


class MaterialStatus(str, Enum):
    """Where a material is in the run, as the coordinator believes (the ground truth decides the
    result: trial_record.scoring)."""
    SEEN = 'seen'                 # confirmed on the belt; waits to be picked
    PICKING = 'picking'           # the loader is on its way to it, or has it
    ON_PLATE = 'on_plate'         # on the youBot's plate
    PLACED = 'placed'             # set down on its destination by the loader
    DELIVERED = 'delivered'       # set down or dropped there by the youBot
    FAILED = 'failed'             # given up (the event says why)
    MISSED = 'missed'             # went off the belt's end unpicked

    @property
    def done(self) -> bool:
        """At its destination, as far as the coordinator knows."""
        return self in (MaterialStatus.PLACED, MaterialStatus.DELIVERED)


@dataclass
class Material:
    id: int
    color: str
    position: np.ndarray
    stamp: float
    hits: int
    status: MaterialStatus = MaterialStatus.SEEN
    attempts: int = 0
    slot: int = -1
    failure: str = ''
    picked: bool = False          # lifted off the belt by the loader
    last_seen: float = -math.inf  # when a frame last showed it
    unload_attempts: int = 0
    # The vision's detection that confirmed it, as reported: its colour and where the frame
    # showed it, at the frame's stamp (``position`` is carried on by the belt model).
    detection: Optional[Detection] = None
    size: float = 0.05            # its class's cube edge [m]
    place: int = -1               # its slot at its destination, once one is kept for it
    # Its unload failed: it may still stand on its plate slot, which is never used again.
    left_on_plate: bool = False
    plate: str = ''               # the youBot whose plate slot it has (or is kept for it)
    # When the arm of a pick under way comes over it (REAIM_LEAD_S before the cup is): from
    # then on what the camera sees of it is not used (infinity: no pick under way).
    hands_on: float = math.inf
    # Its picks on the move all missed: it is picked again once it rests at the end stop, its
    # attempts from this one on (-1: not deferred).
    at_rest_from: int = -1

    @property
    def on_the_plate(self) -> bool:
        """On the youBot's plate: loaded and not unloaded yet, or left there."""
        return self.status == MaterialStatus.ON_PLATE or self.left_on_plate

    def on_plate_of(self, robot: str) -> bool:
        """On the plate of youBot ``robot`` (``on_the_plate``)."""
        return self.on_the_plate and self.plate == robot


@dataclass(frozen=True)
class Tally:
    """The run's counts, from the materials' statuses: the result and the published state both
    take them from here."""
    total: int                    # materials in the batch
    identified: int               # confirmed by the vision
    picked: int                   # lifted off the belt by the loader
    delivered: int                # at their destination (placed or delivered)
    missed: int
    failed: int

    @classmethod
    def of(cls, materials: Sequence['Material'], total: int) -> 'Tally':
        return cls(total=total, identified=len(materials),
                   picked=sum(1 for m in materials if m.picked),
                   delivered=sum(1 for m in materials if m.status.done),
                   missed=sum(1 for m in materials if m.status is MaterialStatus.MISSED),
                   failed=sum(1 for m in materials if m.status is MaterialStatus.FAILED))


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


class LoaderState(Enum):
    """The loader's states: wait for the front material at the pick point; pick it (down onto it
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
    and holds it up until the base stands. In a fleet, a youBot waits at its park for the
    loading pose (WAIT_BAY), and after its last unload until its drive off the pool is clear
    (LEAVE)."""
    WAIT_LOAD = 'wait_load'
    DRIVE = 'drive'
    GRASP = 'grasp'
    CARRY = 'carry'
    RELEASE = 'release'
    LEAVE = 'leave'
    WAIT_BAY = 'wait_bay'
    FOLD = 'fold'
    DONE = 'done'
