"""The loader's way from a lift point onto a place (no ROS): PlaceWay, and how it keeps clear of
what is on the belt and at its end.

A way planned from a lift point a few centimetres over the belt can swing what the cup holds
into the materials riding on the belt or queued at its end stop, or over the stop (a wall
higher than the materials it holds). Where it comes nearer one than the cell's
``swing_clearance``, the loader goes straight up from the lift point first, what the cup holds
RISE_OVER_M over the tallest thing on the belt or at its end, and as much higher again, up to
RISE_LEVELS times, until the way on from there is clear. A Panda's swings from a 4-5 cm lift
had dragged a purple riding ahead off the belt, scraped over the end stop, or sagged 5 cm
beside the purple queued there: the shock drove its wrist past its speed limit, and the motion
was aborted (docs/pipeline.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from cell_layout.link_clearance import link_clearance
from cell_layout.pick_geometry import (
    end_stop_box,
    from_waypoint,
    sweeps_into,
    sweeps_into_box,
    tallest_on_belt,
)
from controllers.arrays import Vector
from controllers.time_optimal import Waypoint

# What the cup holds rises this far over the tallest thing on the belt or at its end, and as
# much again at each try [m], at most RISE_LEVELS times.
RISE_OVER_M = 0.05
RISE_LEVELS = 3

Points = List[Tuple[float, np.ndarray, Any, Any]]


@dataclass
class PlaceWay:
    """A held material's way onto its place (joints), and the rise from there."""
    waypoints: List[Waypoint]     # from the lift point: over the belt's edge, above, down
    then: np.ndarray              # where the cup rises to over the place (not to a pick)
    above: np.ndarray             # above the place (x, y, z)
    above_q: np.ndarray
    onto_plate: bool
    # The materials at the place already (bottom centre, edge), and the held one's edge.
    neighbours: List[Tuple[np.ndarray, float]] = field(default_factory=list)
    held: float = 0.0

    def stopping_above(self) -> List[Waypoint]:
        """The same way, at rest above the place before it goes straight down (a way that
        blends through that point can come down onto the place on a curve)."""
        return [replace(w, stop=True) if w.q is self.above_q else w for w in self.waypoints]

    @property
    def rise(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """What the cup adopts for its rise from the place (CupPlace.adopt)."""
        return self.then, self.above, self.above_q, self.onto_plate

# Something on the belt: its name, and where it is (each a bottom centre and an edge [m]).
Riding = Tuple[str, Sequence[Tuple[Vector, float]]]


def near_on_belt(lay: CellLayout, motion: Points, held: float, riding: Sequence[Riding]
                 ) -> str:
    """What ``motion`` carries what the cup holds (a cube of edge ``held``) within the cell's
    swing clearance of: the end stop, or the name of one of ``riding`` ('': nothing)."""
    if not motion:
        return ''
    qs = [p[1] for p in motion]
    stop = end_stop_box(lay)
    if stop is not None and sweeps_into_box(lay, qs, stop, held, lay.swing_clearance):
        return 'the end stop'
    near = next((name for name, where in riding
                 if sweeps_into(lay, qs, where, held, clearance=lay.swing_clearance)), '')
    links = link_clearance(lay)
    return near or (links.strikes(qs) if links is not None else '')


def rise_first(lay: CellLayout, lift: Optional[Vector], held: float, q_lift: np.ndarray,
               planned: Callable[[List[np.ndarray]], Points],
               riding: Callable[[float], Sequence[Riding]],
               solve: Callable[[np.ndarray, np.ndarray], Optional[np.ndarray]],
               lifted: float) -> Tuple[Points, List[str]]:
    """The motion ``planned`` plans from the lift point ``lift`` (the cup's, in the world; at
    joints ``q_lift``, the points from time ``lifted`` on), ``planned(up)`` through the joints
    ``up`` first, at rest; ``riding(t)``: what is on the belt at time ``t``, in the same
    order at any time (it is checked where it is as the way begins and a second on);
    ``solve(point, seed)``: the joints with the cup at a point. Returns the motion, and for
    each rise, how far and why."""
    motion = planned([])
    after, rises = from_waypoint(motion, q_lift, lifted), []
    for level in range(1, RISE_LEVELS + 1):
        if not after or lift is None:
            break
        t0 = after[0][0]
        near = near_on_belt(lay, after, held, [
            (name, [*now, *later]) for (name, now), (_, later) in zip(riding(t0),
                                                                      riding(t0 + 1.0))])
        if not near:
            break
        high = np.array(lift, float)
        high[2] = max(high[2], lay.belt_top + tallest_on_belt(lay) + held + level * RISE_OVER_M)
        q_high = solve(high, q_lift)
        if q_high is None:
            break
        motion = planned([q_high])
        after = from_waypoint(motion, q_high, lifted)
        rises.append(f'up {high[2] - lift[2]:.3f} m first: its swing came near {near}')
    return motion, rises

