"""Tells when a joint group cannot hold its reference, and why.

A position-controlled arm that holds a pose off its reference is almost always pushing against
something: its target lies inside the floor, the load plate or a material (the arm stops at
the contact, as the youBot's arm_joint_4 did at 0.86 rad against a held 0.72), or, with no
contact, a load beyond its joints' effort limits. JTC would only report the error; here the
simulator knows the contacts and says which links touch what.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

# Held this far from the reference (rad, or m for a prismatic joint) for CHECKS_TO_WARN checks
# in a row: the group is blocked. A free arm settles within a few milliradians (the youBot's
# largest error over a pipeline trial: 0.009 rad); grippers travel less than this.
HOLD_ERROR = 0.05
CHECK_PERIOD = 0.25            # simulated seconds between checks
CHECKS_TO_WARN = 2


@dataclass
class HoldReport:
    group: str
    blocked: bool
    text: str


class HoldWatch:
    """Watches every joint group of a world; :meth:`update` returns what changed."""

    def __init__(self, world: Any) -> None:
        self._world = world
        self._next = 0.0
        self._count: Dict[Tuple[str, str], int] = {}
        self._blocked: Dict[Tuple[str, str], bool] = {}

    def update(self, now: float) -> List[HoldReport]:
        if now < self._next:
            return []
        self._next = now + CHECK_PERIOD
        reports = []
        for robot_name, robot in self._world.robots.items():
            for name, group in robot.controllers.items():
                key = (robot_name, name)
                worst = self.hold_error(group)
                self._count[key] = self._count.get(key, 0) + 1 if worst else 0
                blocked = self._count[key] >= CHECKS_TO_WARN
                if blocked != self._blocked.get(key, False):
                    self._blocked[key] = blocked
                    label = f'{robot_name}/{name}'
                    reports.append(HoldReport(label, blocked, (
                        self.explain(group, *worst) if blocked and worst else
                        f'{label} is back at its reference')))
        return reports

    @staticmethod
    def hold_error(group: Any) -> Optional[Tuple[str, float]]:
        """The worst joint and its error, if the group holds still and is off by HOLD_ERROR."""
        desired = group.desired
        if np.any(desired.velocities != 0.0):
            return None                              # following a trajectory: not holding
        position, _ = group.actual()
        error = np.abs(desired.positions - position)
        i = int(np.argmax(error))
        return (group.joint_names[i], float(error[i])) if error[i] > HOLD_ERROR else None

    def explain(self, group: Any, joint: str, error: float) -> str:
        label = f'{group.robot.config.name}/{group.config.name}'
        contacts = self._world.contacts_of(group)
        why = (f'in contact: {", ".join(contacts)}' if contacts else
               'touching nothing: its load exceeds the effort limits')
        return f'{label} holds {joint} {error:.3f} from its reference, {why}'
