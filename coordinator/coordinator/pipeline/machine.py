"""One robot's state machine: its state, the state's deadline, a handler per state, and the
table of the transitions it may make (``TRANSITIONS``), checked as each state is entered."""
from __future__ import annotations

import logging
import math
import os
from enum import Enum
from typing import Callable, ClassVar, Dict, FrozenSet, List, Mapping, Optional, Tuple

from coordinator.pipeline.model import Observation, Points, Settings
from coordinator.pipeline.record import EventLog
from coordinator.pipeline.robots import Arm
from trial_record.events import EventKind

# Set (to 1) in the test suite: a transition the table does not allow raises TransitionError.
# Elsewhere it is logged, counted, and made: a run is not ended by its own bookkeeping.
STRICT_ENV = 'ROBOT_SIM_STRICT_TRANSITIONS'


class TransitionError(RuntimeError):
    """A machine entered a state its transition table does not allow from where it was."""


Transitions = Mapping[Enum, FrozenSet[Enum]]


class Machine:
    """One robot's state machine: its state, that state's deadline and a handler per state.
    Every transition goes through ``enter``, which checks it against ``TRANSITIONS`` (the
    states each state may be followed by) and reports it as a ``state`` event."""

    name = ''
    TRANSITIONS: ClassVar[Transitions] = {}

    def __init__(self, arm: Arm, log: EventLog, settings: Settings, initial: Enum) -> None:
        self.arm, self.log, self.s = arm, log, settings
        self.state = initial
        self.deadline = math.inf
        self.handlers: Dict[Enum, Callable[[Observation], None]] = {}
        self.wrong_transitions: List[Tuple[float, Enum, Enum]] = []

    def enter(self, state: Enum, now: float, budget: float) -> None:
        if state not in self.TRANSITIONS.get(self.state, frozenset()):
            self._wrong(self.state, state, now)
        self.state = state
        self.deadline = now + budget
        self.log.event(now, EventKind.STATE, self.name, detail=state.value)

    def _wrong(self, was: Enum, state: Enum, now: float) -> None:
        what = (f'{self.name}: {was.value} -> {state.value} at {now:.3f} s is not in its '
                'transition table')
        if os.environ.get(STRICT_ENV) == '1':
            raise TransitionError(what)
        self.wrong_transitions.append((now, was, state))
        logging.getLogger('coordinator.pipeline').error(what)

    def move(self, state: Enum, obs: Observation, points: Points,
             start: Optional[float] = None) -> None:
        """Send this machine's arm a motion and enter ``state``, due by the motion's end (as
        the port scheduled it) plus the settle margin."""
        motion = self.arm.send(points, start)
        self.enter(state, obs.now, motion.end - obs.now + self.s.settle_margin)

    def late(self, now: float) -> bool:
        return now > self.deadline

    def tick(self, obs: Observation) -> None:
        self.handlers[self.state](obs)

    def arrival(self, obs: Observation) -> Optional[bool]:
        """The arm's last motion: True once arrived, None while it may still arrive, False once
        this state's deadline has passed without it (a stalled arm)."""
        arrived = self.arm.arrived(obs)
        if arrived is None and self.late(obs.now):
            return False
        return arrived

    def motion_over(self, obs: Observation, what: str) -> bool:
        """Whether the arm's last motion is over: arrived, or stalled (then reported)."""
        arrived = self.arrival(obs)
        if arrived is False:
            self.log.event(obs.now, EventKind.ARM_STALLED, self.arm.name,
                           detail=f'{what} not reached')
        return arrived is not None


def transition_table(rows: Mapping[Enum, Tuple[Enum, ...]]) -> Transitions:
    """A machine's table from its rows (each state: the states that may follow it), every state
    of its enum given a row (a final state's is empty)."""
    states = set(type(next(iter(rows))))
    missing = states - set(rows)
    if missing:
        raise ValueError(f'no row for {sorted(s.value for s in missing)}')
    return {state: frozenset(rows[state]) for state in rows}
