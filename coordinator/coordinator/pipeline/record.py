"""The run's record (no ROS): its events, each sent out through the ports as it happens, and
the counts the result takes from them (grasps per arm). The only writer of both."""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional

from coordinator.pipeline.model import Material, Ports
from trial_record.events import Event, EventKind


class EventLog:
    def __init__(self, ports: Ports, arms: List[str]) -> None:
        self.ports = ports
        self.events: List[Event] = []
        self.grasps: Dict[str, List[int]] = {arm: [0, 0] for arm in arms}   # attempts, successes

    def event(self, now: float, kind: EventKind, robot: str = '', m: Optional[Material] = None,
              detail: str = '') -> None:
        e = Event(now, kind, robot, m.id if m else -1, m.color if m else '', detail)
        self.events.append(e)
        self.ports.event(e)

    def count_grasp(self, arm: str, success: bool = False) -> None:
        self.grasps[arm][1 if success else 0] += 1

    @property
    def grasp_attempts(self) -> int:
        return sum(a for a, _ in self.grasps.values())

    @property
    def grasp_successes(self) -> int:
        return sum(s for _, s in self.grasps.values())

    def by_robot(self, roles: Mapping[str, str]) -> Dict[str, Dict[str, Any]]:
        """Each robot's grasps (``roles``: its role by its name)."""
        return {robot: {'role': role, 'attempts': self.grasps[robot][0],
                        'successes': self.grasps[robot][1]} for robot, role in roles.items()}
