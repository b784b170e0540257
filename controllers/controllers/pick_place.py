"""A suction pick off a moving belt, in Cartesian waypoints, and the timings of a pick and a
place (no ROS): the coordinator's pick planner (coordinator.pipeline) builds on it.

The tool points straight down. The pick follows the material: hover above where it will be,
descend onto its top face while moving with the belt, stay on it while the suction engages,
then lift. Times are absolute (simulated) seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Tuple

import numpy as np

Waypoint = Tuple[float, np.ndarray]          # (time [s], tool position in the world [m])
# Where a material's centre is (will be) at a time: its predicted track on the belt.
Track = Callable[[float], np.ndarray]


@dataclass(frozen=True)
class PickTiming:
    hover: float = 0.10          # height above the material's top for the approach [m]
    contact_gap: float = 0.0     # tool tip above the top face at contact [m]
    descend: float = 0.6         # hover -> contact [s], moving with the belt
    dwell: float = 0.4           # on the material while the suction engages [s]
    lift: float = 0.8            # contact -> lift height [s]
    lift_height: float = 0.15    # above the belt's top face after the pick [m]
    place_descend: float = 0.8   # above the target -> release [s]
    place_height: float = 0.15   # the straight descent onto a place starts this high [m]
    place_gap: float = 0.003     # the material's bottom above the target surface at release


def follow_pick(track: Track, t_contact: float, size: float, timing: PickTiming = PickTiming(),
                period: float = 0.05) -> Tuple[List[Waypoint], np.ndarray]:
    """The tool's path onto the material whose centre follows ``track`` (carried by the belt,
    held at its end stop, or still), sampled every ``period`` or less: from the hover point,
    ``timing.hover`` over the top face, down onto it by ``t_contact`` while moving with it,
    and on it for the dwell. Also returns the lift point: ``timing.lift_height`` over the
    contact, ahead by half the material's travel over the lift (the tool slows from its speed
    to rest meanwhile), and no further than the track takes it by then (held at an end stop).

    The descent is smooth to the second derivative: its height over the top face is
    ``hover (2 f^3 - f^4)`` with ``f`` running from 1 to 0, so it starts at a vertical speed of
    ``2 hover / descend`` without acceleration, and touches at zero speed and acceleration.
    """
    if not (timing.descend > 0.0 and timing.dwell >= 0.0 and period > 0.0):
        raise ValueError('the descent and the period must take time')
    top = size / 2 + timing.contact_gap
    t_leave = t_contact + timing.dwell
    h = 1e-3
    v_leave = (np.array(track(t_leave), float) - np.array(track(t_leave - h), float)) / h
    v_leave[2] = 0.0

    def on(t: float) -> np.ndarray:
        point: np.ndarray = np.array(track(t), float) + np.array([0.0, 0.0, top])
        return point

    def times(t0: float, t1: float) -> List[float]:
        k = max(1, int(np.ceil((t1 - t0) / period - 1e-9)))
        return [t0 + (t1 - t0) * j / k for j in range(k + 1)]

    out: List[Waypoint] = []
    for t in times(t_contact - timing.descend, t_contact):
        f = (t_contact - t) / timing.descend
        out.append((t, on(t) + np.array([0.0, 0.0, timing.hover * (2 * f ** 3 - f ** 4)])))
    if timing.dwell > 0.0:
        out += [(t, on(t)) for t in times(t_contact, t_leave)[1:]]
    # Ahead by half the travel over the lift, but never past where the track holds it (an end
    # stop): met 55 mm before the stop at 0.36 m/s, the lift point lay 35 mm beyond it, the
    # cup dragged the material into the stop's wall and the arm stalled, the material held.
    ahead = v_leave * timing.lift / 2
    held = np.array(track(t_leave + timing.lift / 2), float) - np.array(track(t_leave), float)
    held[2] = 0.0
    if float(np.linalg.norm(held)) < float(np.linalg.norm(ahead)) - 1e-9:
        ahead = held
    lift = on(t_leave) + ahead + np.array([0.0, 0.0, timing.lift_height])
    return out, lift
