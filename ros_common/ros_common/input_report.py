"""What a node refused or changed of its inputs, per input, for /diagnostics.

A log line tells the person at the node's terminal; the sender of a refused command is
usually another program on another machine. The node counts every rejection and clamp per
input (a robot's cmd_vel, an arm's trajectories) and kind, and reports them as
diagnostic_msgs/DiagnosticStatus, as diagnostic_updater-based drivers do: one status per
input, WARN while it has refused something in the last period, OK after, with the counts and
the last reason as values. No ROS here; the node publishes.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Tuple

OK, WARN = 0, 1      # diagnostic_msgs/DiagnosticStatus levels


@dataclass
class _Input:
    counts: Dict[str, int] = field(default_factory=dict)
    last_reason: str = ''
    new: int = 0          # since the last report


@dataclass(frozen=True)
class InputStatus:
    name: str             # "<robot>/<input>"
    hardware_id: str      # the robot
    level: int
    message: str
    values: Tuple[Tuple[str, str], ...]


class InputReport:
    """Counts per (robot, input, kind); :meth:`statuses` says where each input stands."""

    def __init__(self) -> None:
        self._inputs: Dict[Tuple[str, str], _Input] = {}

    def add(self, robot: str, input_name: str, kind: str, reason: str) -> None:
        entry = self._inputs.setdefault((robot, input_name), _Input())
        entry.counts[kind] = entry.counts.get(kind, 0) + 1
        entry.last_reason = reason
        entry.new += 1

    def __bool__(self) -> bool:
        return bool(self._inputs)

    def statuses(self) -> List[InputStatus]:
        """Every input with something refused so far; WARN if anything since the last call."""
        out = []
        for (robot, name), entry in sorted(self._inputs.items()):
            total = sum(entry.counts.values())
            if entry.new:
                level, message = WARN, (f'{entry.new} refused or changed since the last report: '
                                        f'{entry.last_reason}')
            else:
                level, message = OK, f'nothing refused since the last report ({total} in all)'
            values = tuple(sorted((kind, str(n)) for kind, n in entry.counts.items())) + (
                ('last reason', entry.last_reason),)
            out.append(InputStatus(f'{robot}/{name}', robot, level, message, values))
            entry.new = 0
        return out
