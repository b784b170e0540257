"""The belt's speed as the cell senses it (no ROS): from the vision's tracks of the materials
the belt carries freely, and from the conveyor drive's encoder where the cell has one
(``measured``: its speed over its own window, weighed with the tracks' by its error).

A real belt's speed is not its set point: it drifts with load, wear and its drive (a perturbed
world drifts it by up to 15 %), and a material the cell meets 2 s after it last saw it is off
by that drift times the distance. Each track the camera follows gives the belt's speed as the
slope of its positions against the belt's running time (a pause in between is no motion); the
estimate is the tracks' slopes of the last ``window`` seconds, weighted by how well each is
known. Without a usable track yet, the last estimate holds, and before any, the set point.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass, replace
from typing import Deque, Dict, List, Optional, Tuple

# The slope of a track is taken over its sightings of the last WINDOW_S seconds of running
# time (the perturbed belt's drift changes its speed by at most ~0.7 % of it per second, so a
# longer window would average over a speed that is no longer the belt's) [s].
WINDOW_S = 1.5
# A track's sightings give a slope once they span this much running time (a material is
# confirmed after 8 frames, 0.47 s at the camera's 15 Hz: its own track tells the speed it is
# picked at) [s].
MIN_SPAN_S = 0.2
# A track's slope is taken over at least this many sightings (its last ones, older than the
# window if it has no more).
MIN_POINTS = 4
# A sighting's position is known no better than this along the belt (the camera's pixel is
# 3 mm on the belt; a noiseless stand-in must not claim an exact speed) [m].
MIN_POSITION_STD_M = 0.0005


@dataclass(frozen=True)
class BeltSpeed:
    """The belt's speed while it runs, as estimated now."""
    speed: float            # [m/s]
    std: float              # its standard error [m/s] (inf: the set point, not measured)
    source: str             # 'vision' (the tracks'), 'encoder' (the drive's, with the tracks'),
    #                         or 'set point' before either
    tracks: int             # how many tracks the estimate is made of
    stamp: float            # the running time of the newest sighting it uses [s]
    age: float = 0.0        # how much running time has passed since, at the last update [s]

    def describe(self) -> str:
        """As the events say it."""
        if self.source == 'set point':
            return f'belt {self.speed:.3f} m/s (set point)'
        return (f'belt {self.speed:.4f} +- {self.std:.4f} m/s ({self.source}, {self.tracks} '
                f'tracks, {self.age:.1f} s old)')


class BeltSpeedEstimate:
    """Feed it each sighting of a material the belt carries freely (``sighted``, by the
    belt's running time), read ``current``."""

    def __init__(self, set_point: float, window: float = WINDOW_S,
                 min_span: float = MIN_SPAN_S) -> None:
        if not (math.isfinite(set_point) and set_point >= 0.0):
            raise ValueError(f'set_point must be finite and >= 0, got {set_point}')
        if not (window > 0.0 and 0.0 < min_span <= window):
            raise ValueError(f'need 0 < min_span <= window, got {min_span}, {window}')
        self.window, self.min_span = window, min_span
        self._tracks: Dict[int, Deque[Tuple[float, float]]] = {}
        self.current = BeltSpeed(set_point, math.inf, 'set point', 0, -math.inf)
        self._newest = -math.inf
        self._encoder: Optional[Tuple[float, float, float]] = None   # (running time, speed, std)

    def sighted(self, track: int, running_time: float, x: float) -> None:
        """Track ``track`` was at ``x`` (along the belt [m]) at ``running_time`` (the belt's
        running time at the frame's stamp [s]): it rides on the belt, carried freely."""
        if not (math.isfinite(running_time) and math.isfinite(x)):
            return
        points = self._tracks.setdefault(track, collections.deque())
        if points and running_time <= points[-1][0]:
            # (A second detection in the same stretch of running time: the belt was stopped
            # between the frames, which says nothing of its speed.)
            points[-1] = (points[-1][0], x)
            return
        points.append((running_time, x))
        self._newest = max(self._newest, running_time)

    def measured(self, running_time: float, speed: float, std: float) -> None:
        """The conveyor drive's encoder read ``speed`` +- ``std`` [m/s] up to
        ``running_time``: in the estimate with the tracks', each by how well it is known."""
        if math.isfinite(speed) and math.isfinite(std) and std > 0.0:
            self._encoder = (running_time, speed, std)
            self._newest = max(self._newest, running_time)

    def forget(self, track: int) -> None:
        """The track no longer rides freely (lifted, held at the stop, gone)."""
        self._tracks.pop(track, None)

    def update(self, running_time: float) -> BeltSpeed:
        """The estimate at the belt's ``running_time`` from the tracks' sightings of the last
        window (kept as it was, older, if no track spans enough of it)."""
        since = self._newest - self.window
        slopes: List[Tuple[float, float]] = []
        for track in list(self._tracks):
            points = self._tracks[track]
            # (Its last MIN_POINTS whatever their age: a coordinator that lags sees a frame
            # in 16, and a window would never hold enough of them.)
            while len(points) > MIN_POINTS and points[0][0] < since:
                points.popleft()
            if not points:
                del self._tracks[track]
                continue
            fit = _slope(points)
            if fit is not None and points[-1][0] - points[0][0] >= self.min_span:
                slopes.append(fit)
        source = 'vision'
        if self._encoder is not None and self._encoder[0] >= since:
            slopes.append((self._encoder[1], self._encoder[2] ** 2))
            source = 'encoder'
        if slopes:
            weights = [1.0 / var for _, var in slopes]
            total = sum(weights)
            speed = sum(w * s for w, (s, _) in zip(weights, slopes)) / total
            tracks = len(slopes) - (source == 'encoder')
            self.current = BeltSpeed(max(0.0, speed), math.sqrt(1.0 / total), source,
                                     tracks, self._newest)
        if math.isfinite(self.current.stamp):
            self.current = replace(self.current,
                                   age=max(0.0, running_time - self.current.stamp))
        return self.current


def _slope(points: Deque[Tuple[float, float]]) -> Optional[Tuple[float, float]]:
    """A least-squares line through (running time, x): its slope and the slope's variance."""
    n = len(points)
    if n < MIN_POINTS:
        return None
    t_mean = sum(t for t, _ in points) / n
    x_mean = sum(x for _, x in points) / n
    stt = sum((t - t_mean) ** 2 for t, _ in points)
    if stt <= 0.0:
        return None
    slope = sum((t - t_mean) * (x - x_mean) for t, x in points) / stt
    residual = sum((x - x_mean - slope * (t - t_mean)) ** 2 for t, x in points)
    variance = max(residual / (n - 2), MIN_POSITION_STD_M ** 2) / stt
    return slope, variance
