"""What a run of the cell's controller reports: its events, and its counts at the end. The
controller writes them; the score (``scoring``) judges them against the ground truth."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Dict, List


class EventKind(str, Enum):
    """What happened (an event's kind; its value is the word the result and
    ``PipelineEvent.kind`` carry, and what it reads as in text)."""
    SEEN = 'seen'                           # the vision reported a new material
    TRACKING = 'tracking'
    BELT_STARTED = 'belt_started'
    BELT_STOPPED = 'belt_stopped'
    PICKED = 'picked'
    PLACED = 'placed'
    LOADED = 'loaded'
    LOADING_OVER = 'loading_over'           # no material will come any more
    GRASP_MISSED = 'grasp_missed'           # tried again
    GRASP_FAILED = 'grasp_failed'           # given up
    IK_FAILED = 'ik_failed'
    ARM_STALLED = 'arm_stalled'
    REPLANNED = 'replanned'
    RETURNING = 'returning'
    WAITING_FOR_LOAD = 'waiting_for_load'
    DEPARTING = 'departing'
    DRIVING = 'driving'
    DRIVE_STALLED = 'drive_stalled'
    ARRIVED = 'arrived'
    UNLOAD_GRASPED = 'unload_grasped'
    DELIVERED = 'delivered'
    FAILED = 'failed'
    MISSED = 'missed'                       # went off the belt's end unpicked
    FINISHED = 'finished'
    STATE = 'state'                         # a machine changed state (detail: the new one)

    def __str__(self) -> str:
        return str(self.value)


@dataclass(frozen=True)
class Event:
    time: float
    kind: EventKind
    robot: str = ''
    material: int = -1
    color: str = ''
    detail: str = ''


@dataclass
class RunResult:
    status: str                        # completed, incomplete, timeout, node_timeout, error
    completion_time: float             # sim time from start to both robots home [s]
    total: int
    identified: int                    # materials the vision reported with a colour
    picked: int                        # materials the loader lifted off the belt
    delivered: int                     # materials at their destination (as the machine saw it)
    grasp_attempts: int                # both arms
    grasp_successes: int
    missed: int                        # went off the belt end unpicked
    failed: int
    message: str = ''
    materials: List[Dict[str, Any]] = field(default_factory=list)
    # Per role, as the paper splits its rates: the loader's picks (the paper's Zu 12), the
    # transports' unloads (its youBot); and per robot (name: role, attempts, successes).
    loader_grasp_attempts: int = 0
    loader_grasp_successes: int = 0
    transport_grasp_attempts: int = 0
    transport_grasp_successes: int = 0
    robot_grasps: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    loaded: int = 0                    # materials the loader set down on a youBot's plate
    trips: int = 0                     # loads the youBot set off with
    belt_stops: int = 0                # times the belt stopped while loading (a full queue)
    # Several youBots: per youBot, its trips, the materials it set off with (carried) and those
    # of its plate it delivered ({} for one youBot: the run's own counts are its).
    transports: Dict[str, Dict[str, int]] = field(default_factory=dict)
