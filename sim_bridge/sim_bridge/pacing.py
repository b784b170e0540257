"""Real-time pacing of fixed physics steps, and the achieved real-time factor."""
from __future__ import annotations

import math
from collections import deque
from typing import Deque, Optional, Tuple


class Pacer:
    """Decides how many physics steps are due at a given wall time.

    ``real_time_factor`` > 0 paces simulated time to that multiple of wall time; 0 means as
    fast as possible. When the simulation cannot keep up it runs at most ``max_burst`` steps per
    call and then re-anchors, so a stall (a slow camera frame, a paused process) does not turn
    into a long burst of catch-up steps with no callbacks serviced in between.
    """

    def __init__(self, time_step: float, real_time_factor: float, max_burst: int = 64) -> None:
        if not (time_step > 0.0 and math.isfinite(time_step)):
            raise ValueError(f'time_step must be > 0, got {time_step}')
        if not (real_time_factor >= 0.0 and math.isfinite(real_time_factor)):
            raise ValueError(f'real_time_factor must be >= 0, got {real_time_factor}')
        if max_burst < 1:
            raise ValueError(f'max_burst must be >= 1, got {max_burst}')
        self.time_step = time_step
        self.real_time_factor = real_time_factor
        self.max_burst = max_burst
        self._anchor_wall: Optional[float] = None
        self._steps_since_anchor = 0

    @property
    def as_fast_as_possible(self) -> bool:
        return self.real_time_factor == 0.0

    def restart(self) -> None:
        """Forget the schedule (after a pause, or a lock-step phase)."""
        self._anchor_wall = None
        self._steps_since_anchor = 0

    def steps_due(self, wall_now: float) -> int:
        if self.as_fast_as_possible:
            return self.max_burst
        if self._anchor_wall is None:
            self._anchor_wall = wall_now
            self._steps_since_anchor = 0
        target = math.floor((wall_now - self._anchor_wall) * self.real_time_factor
                            / self.time_step + 1e-9)
        due = target - self._steps_since_anchor
        if due > self.max_burst:
            # Behind schedule: do a burst now and re-anchor the schedule after it.
            self._anchor_wall = wall_now
            self._steps_since_anchor = -self.max_burst
            due = self.max_burst
        return max(0, due)

    def record(self, steps: int) -> None:
        self._steps_since_anchor += steps

    def wall_until_next(self, wall_now: float) -> float:
        """Wall seconds until the next step is due (0 when one is due now)."""
        if self.as_fast_as_possible or self._anchor_wall is None:
            return 0.0
        next_wall = (self._anchor_wall + (self._steps_since_anchor + 1) * self.time_step
                     / self.real_time_factor)
        return max(0.0, next_wall - wall_now)


class RtfMeter:
    """Real-time factor over a sliding window of (wall, sim) samples."""

    def __init__(self, window: float = 5.0) -> None:
        self.window = window
        self._samples: Deque[Tuple[float, float]] = deque()

    def add(self, wall: float, sim: float) -> None:
        self._samples.append((wall, sim))
        while len(self._samples) > 2 and wall - self._samples[0][0] > self.window:
            self._samples.popleft()

    def reset(self) -> None:
        self._samples.clear()

    def value(self) -> Optional[float]:
        if len(self._samples) < 2:
            return None
        (w0, s0), (w1, s1) = self._samples[0], self._samples[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else None
