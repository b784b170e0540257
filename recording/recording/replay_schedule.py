"""When each recorded message is due on the wall clock during replay."""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class ReplaySchedule:
    """Maps bag time to wall time: ``wall = wall_start + (bag - bag_start) / rate``.

    ``bag_start`` is the bag's first timestamp plus the start offset; messages before it are
    skipped. ``restart`` begins a new loop pass at the current wall time.
    """

    bag_first_ns: int
    rate: float = 1.0
    start_offset_s: float = 0.0
    wall_start: float = 0.0

    def __post_init__(self) -> None:
        if not (self.rate > 0.0 and math.isfinite(self.rate)):
            raise ValueError(f'rate must be > 0, got {self.rate}')
        if not (self.start_offset_s >= 0.0 and math.isfinite(self.start_offset_s)):
            raise ValueError(f'start offset must be >= 0, got {self.start_offset_s}')

    @property
    def bag_start_ns(self) -> int:
        return self.bag_first_ns + round(self.start_offset_s * 1e9)

    def skip(self, bag_ns: int) -> bool:
        return bag_ns < self.bag_start_ns

    def due(self, bag_ns: int) -> float:
        return self.wall_start + (bag_ns - self.bag_start_ns) * 1e-9 / self.rate

    def bag_time_at(self, wall: float) -> int:
        """The bag time that the replay has reached at a wall time (for /clock)."""
        return self.bag_start_ns + round(max(0.0, wall - self.wall_start) * self.rate * 1e9)

    def restart(self, wall_now: float) -> None:
        self.wall_start = wall_now
