"""The belt's travel as its drive's encoder counts it (no ROS): where the conveyor has an encoder,
how far the belt carried what rides on it between two times is read off the counts, not
reckoned from a speed. A material last seen 4 s before the arm meets it was off by the belt's
drift times those 4 s (a perturbed belt drifts by up to 15 %); from the counts it is off by a
count or two. The drive reports at its own rate (10 Hz by default); between two readings the
travel is taken as linear, and past the newest one it is unknown (``travel`` says None)."""
from __future__ import annotations

import bisect
import math
from typing import Callable, List, Optional, Tuple

# Readings kept, newest last: enough to carry a material from its last sighting to its pick
# (the camera sees the belt's first metre; a material is met up to 8 s after) [s].
KEEP_S = 30.0
# The encoder's speed is its travel over this much time before its newest reading [s].
SPEED_WINDOW_S = 0.5


class BeltTravel:
    def __init__(self, resolution: float) -> None:
        if not (math.isfinite(resolution) and resolution > 0.0):
            raise ValueError(f'resolution must be > 0, got {resolution}')
        self.resolution = resolution
        self._t: List[float] = []
        self._x: List[float] = []
        # The belt's travel that what rides on it has been carried to (``carry``).
        self._carried_to: Optional[float] = None

    def read(self, stamp: float, travel: float) -> None:
        """The encoder read ``travel`` [m] at ``stamp`` [s] (readings in time order; an older
        or repeated one, or one not finite, is ignored)."""
        if not (math.isfinite(stamp) and math.isfinite(travel)):
            return
        if self._t and stamp <= self._t[-1]:
            return
        self._t.append(stamp)
        self._x.append(travel)
        drop = bisect.bisect_left(self._t, stamp - KEEP_S)
        if drop > 1:
            del self._t[:drop - 1], self._x[:drop - 1]

    @property
    def newest(self) -> float:
        """The newest reading's stamp (-inf: none yet)."""
        return self._t[-1] if self._t else -math.inf

    def at(self, t: float) -> Optional[float]:
        """The belt's travel at ``t`` (between readings, linear); None outside them."""
        if not self._t or t > self._t[-1] or t < self._t[0]:
            return None
        k = bisect.bisect_left(self._t, t)
        if self._t[k] == t:
            return self._x[k]
        t0, t1, x0, x1 = self._t[k - 1], self._t[k], self._x[k - 1], self._x[k]
        return x0 + (x1 - x0) * (t - t0) / (t1 - t0)

    def travel(self, t0: float, t1: float) -> Optional[float]:
        """How far the belt moved from ``t0`` to ``t1`` (None if either is outside the
        readings)."""
        a, b = self.at(t0), self.at(t1)
        return None if a is None or b is None else b - a

    def speed(self, running_time: Callable[[float, float], float]
              ) -> Optional[Tuple[float, float]]:
        """The belt's speed over the last SPEED_WINDOW_S before the newest reading, and its
        standard error (a count at each end) [m/s], by ``running_time`` (how long the belt
        ran between two times: a stop in between is no motion); None with less than that
        span of readings, or a belt that ran less than half of it."""
        if not self._t:
            return None
        t1 = self._t[-1]
        t0 = t1 - SPEED_WINDOW_S
        moved, ran = self.travel(t0, t1), running_time(t0, t1)
        if moved is None or ran < SPEED_WINDOW_S / 2:
            return None
        return moved / ran, math.sqrt(2.0) * self.resolution / ran


    def estimate(self, t: float, speed: float,
                 running_time: Callable[[float, float], float]) -> Optional[float]:
        """The belt's travel at ``t``: as read up to the newest reading, and past it at
        ``speed`` for as long as the belt ran; None before the first reading."""
        if not self._t or t < self._t[0]:
            return None
        if t <= self._t[-1]:
            return self.at(t)
        return self._x[-1] + speed * running_time(self._t[-1], t)

    def carry(self, t0: float, t1: float, speed: float,
              running_time: Callable[[float, float], float]) -> float:
        """How far to carry what rides on the belt from ``t0`` to ``t1``: from where it was
        last carried to (on the belt's travel) to where the readings put the belt at ``t1``.
        Between two readings the travel is reckoned at ``speed``; the next reading makes good
        what that got wrong, and a shortfall (reckoned too far) is held back until the belt
        has made it up, never carried backwards. (Reckoned afresh from each reading instead,
        what the speed got wrong between readings was never made good: at 10 Hz readings and
        a speed 13 % off, a material out of the camera's view drifted 7 mm from where it was.)"""
        at = self.estimate(t1, speed, running_time)
        if at is None or self._carried_to is None:
            travel = carried(self, t0, t1, speed, running_time)
            self._carried_to = at
            return travel
        travel = at - self._carried_to
        if travel <= 0.0:
            return 0.0
        self._carried_to = at
        return travel


def carried(encoder: Optional[BeltTravel], t0: float, t1: float, speed: float,
            running_time: Callable[[float, float], float]) -> float:
    """How far the belt carried what rides on it from ``t0`` to ``t1``: as its ``encoder``
    counted it up to its newest reading, and from there (or without one, or before its first
    reading) at ``speed`` for as long as it ran (``running_time`` between two times)."""
    counted = encoder.newest if encoder is not None else -math.inf
    read = encoder.travel(t0, min(t1, counted)) if encoder is not None and t0 < counted else None
    if read is None:
        return speed * running_time(t0, t1)
    return read + speed * running_time(max(t0, counted), t1)
