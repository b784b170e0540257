"""Planning a suction pick off a moving belt and a place, in Cartesian waypoints (no ROS).

The tool points straight down. The pick follows the material: hover above where it will be,
descend onto its top face while moving with the belt, stay on it while the suction engages,
then lift. The place goes above the target, down until the material's bottom is just above the
target surface, releases, and rises again. Times are absolute (simulated) seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Sequence, Tuple

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


def predict(position: Sequence[float], stamp: float, velocity: Sequence[float],
            t: float) -> np.ndarray:
    return np.asarray(position, float) + np.asarray(velocity, float) * (t - stamp)


def pick_waypoints(position: Sequence[float], stamp: float, velocity: Sequence[float],
                   t_contact: float, size: float, timing: PickTiming = PickTiming()
                   ) -> Tuple[List[Waypoint], float]:
    """Tool waypoints to pick the material seen at ``position`` (its centre) at ``stamp``,
    moving at ``velocity``, touching it at ``t_contact``; and the time to switch suction on."""
    top = size / 2 + timing.contact_gap

    def at(t: float, height: float) -> np.ndarray:
        p = predict(position, stamp, velocity, t)
        p[2] += top + height
        return p
    t_hover = t_contact - timing.descend
    t_leave = t_contact + timing.dwell
    lifted = at(t_leave, 0.0)
    lifted[2] = np.asarray(position)[2] - size / 2 + timing.lift_height + size
    # Dense while moving with the belt, so that the joint interpolation stays on the path.
    descend = [(t_contact - timing.descend * f, at(t_contact - timing.descend * f,
                                                   timing.hover * f ** 2))
               for f in (1.0, 2 / 3, 1 / 3)]
    dwell = [(t_contact + timing.dwell * f, at(t_contact + timing.dwell * f, 0.0))
             for f in (0.0, 0.5, 1.0)]
    waypoints = descend + dwell + [(t_leave + timing.lift, lifted)]
    return waypoints, t_contact + timing.dwell / 4


def follow_pick(track: Track, t_contact: float, size: float, timing: PickTiming = PickTiming(),
                period: float = 0.05) -> Tuple[List[Waypoint], np.ndarray]:
    """The tool's path onto the material whose centre follows ``track`` (carried by the belt,
    held at its end stop, or still), sampled every ``period`` or less: from the hover point,
    ``timing.hover`` over the top face, down onto it by ``t_contact`` while moving with it,
    and on it for the dwell. Also returns the lift point: ``timing.lift_height`` over the
    contact, ahead by half the material's travel over the lift (the tool slows from its speed
    to rest meanwhile).

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
        return np.array(track(t), float) + np.array([0.0, 0.0, top])

    def times(t0: float, t1: float) -> List[float]:
        k = max(1, int(np.ceil((t1 - t0) / period - 1e-9)))
        return [t0 + (t1 - t0) * j / k for j in range(k + 1)]

    out: List[Waypoint] = []
    for t in times(t_contact - timing.descend, t_contact):
        f = (t_contact - t) / timing.descend
        out.append((t, on(t) + np.array([0.0, 0.0, timing.hover * (2 * f ** 3 - f ** 4)])))
    if timing.dwell > 0.0:
        out += [(t, on(t)) for t in times(t_contact, t_leave)[1:]]
    lift = on(t_leave) + v_leave * timing.lift / 2 + np.array([0.0, 0.0, timing.lift_height])
    return out, lift


def place_waypoints(t_above: float, target: Sequence[float], size: float,
                    timing: PickTiming = PickTiming()) -> Tuple[List[Waypoint], float]:
    """Tool waypoints to set the held material (tool on its top face) down with its centre at
    ``target`` (the surface point it rests on); and the time to release."""
    surface = np.asarray(target, float)
    release = surface + np.array([0.0, 0.0, size + timing.place_gap])
    above = release + np.array([0.0, 0.0, timing.place_height])
    t_release = t_above + timing.place_descend
    return ([(t_above, above), (t_release, release),
             (t_release + 0.3, release.copy()),
             (t_release + 0.3 + timing.place_descend, above.copy())], t_release + 0.1)


def plate_slots(centre: Sequence[float], yaw: float, size: float, count: int,
                pitch: float = 0.075, columns: int = 3) -> List[np.ndarray]:
    """Places for ``count`` materials on a load plate, in rows of ``columns``, around the
    plate's centre (a point on its top surface)."""
    rows = -(-count // columns)
    c, s = np.cos(yaw), np.sin(yaw)
    out = []
    for k in range(count):
        r, col = divmod(k, columns)
        x = (r - (rows - 1) / 2) * pitch
        y = (col - (columns - 1) / 2) * pitch
        out.append(np.asarray(centre, float) + np.array([c * x - s * y, s * x + c * y, 0.0]))
    return out
