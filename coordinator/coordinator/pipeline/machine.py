"""One robot's state machine: its state, the state's deadline, a handler per state."""
from __future__ import annotations

import math
from enum import Enum
from typing import (
    TYPE_CHECKING,
    Callable,
    Dict,
    Optional,
)

from coordinator.pipeline.model import (
    EventKind,
    Motion,
    Observation,
    Points,
)

if TYPE_CHECKING:
    from coordinator.pipeline.shared import Shared


class Machine:
    """One robot's state machine: its state, that state's deadline and a handler per state.
    Every transition goes through ``enter``, which reports it as a ``state`` event."""

    name = ''
    arm = ''

    def __init__(self, run: 'Shared', initial: Enum) -> None:
        self.run = run
        self.state = initial
        self.deadline = math.inf
        self.handlers: Dict[Enum, Callable[[Observation], None]] = {}

    def enter(self, state: Enum, now: float, budget: float) -> None:
        self.state = state
        self.deadline = now + budget
        self.run.event(now, EventKind.STATE, self.name, detail=state.value)

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
            self.run.event(obs.now, EventKind.ARM_STALLED, self.arm, detail=f'{what} not reached')
        return arrived is not None
