"""The geometry of the loader's picks and places (no ROS, no state): where its way crosses the
belt's near edge, whether a swing of its joints passes low over the belt, the straight lift out
of a queue, the points over a place, and whether two IK solutions lie on one branch. The
coordinator's loader (coordinator/pipeline/loader.py) plans with these; each has its own unit
tests (tests/unit/test_pick_geometry.py)."""
from __future__ import annotations

import math
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from cell_layout.reach import tool_points, tool_positions
from controllers.arrays import Vector
from controllers.pick_place import PickTiming
from world_description.world_schema import END_STOP_HEIGHT_M, END_STOP_THICKNESS_M

# The cell's pick and place timing: the shortest times of the moves near a material (the
# time-optimal plan may take longer), gentle enough that the cup and the fingers do not knock
# it, and the heights over it (the coordinator's Settings.timing).
CELL_TIMING = PickTiming(hover=0.06, descend=0.3, dwell=0.15, lift=0.2, lift_height=0.07,
                         place_descend=0.15, place_height=0.07)
# The loader crosses the belt's near edge this far outside it, with what it carries (or its
# empty cup) at least this far above the belt's top [m].
EDGE_CLEARANCE_M = 0.05
# A lift out of the end stop's queue keeps to the straight line up through a point this often
# [m].
LIFT_LINE_STEP_M = 0.01
# A swing of the loader's joints keeps what its cup holds (or the cup) this far above anything
# that can ride on the belt wherever it passes over the belt [m].
SWING_CLEARANCE_M = 0.02
# What the cup holds passes the materials at a place this far from them at least, as it comes
# down onto its own slot [m] (the slots leave 1 cm between neighbours).
NEIGHBOUR_CLEARANCE_M = 0.002
# Faces this near (or overlapping by as little) touch; they do not cross [m].
TOUCHING_M = 1e-3
# A motion's samples are checked at this many points between each two (joint-linear) [-].
SWEEP_SUBSTEPS = 4
# Two IK solutions a pick path's sample apart (50 ms) that differ by more than this in a joint
# lie on two branches [rad].
IK_JUMP_RAD = 0.5


def continuous(qs: Sequence[np.ndarray]) -> bool:
    """Whether no joint moves more than IK_JUMP_RAD between two neighbouring solutions."""
    return all(float(np.max(np.abs(b - a))) <= IK_JUMP_RAD for a, b in zip(qs, qs[1:]))


def polar(v: np.ndarray) -> Tuple[float, float]:
    """(reach, angle) of a vector in the plane."""
    return math.hypot(v[0], v[1]), math.atan2(v[1], v[0])


def crossing(g: Callable[[float], float], samples: int = 200) -> float:
    """The first fraction f in [0, 1] where g changes sign (bisected), or the end of [0, 1]
    where |g| is smaller if it does not."""
    fs = np.linspace(0.0, 1.0, samples + 1)
    gs = [g(f) for f in fs]
    for k in range(samples):
        if gs[k] == 0.0 or gs[k] * gs[k + 1] < 0.0:
            lo, hi = fs[k], fs[k + 1]
            for _ in range(30):
                mid = (lo + hi) / 2
                if g(lo) * g(mid) <= 0.0:
                    hi = mid
                else:
                    lo = mid
            return float((lo + hi) / 2)
    return 0.0 if abs(gs[0]) <= abs(gs[-1]) else 1.0


def edge_point(lay: CellLayout, a: Vector, b: Vector, low: float,
               arc: bool = False) -> np.ndarray:
    """Where the way from ``a`` (over the belt) to ``b`` (beside it) crosses the belt's near
    edge, EDGE_CLEARANCE_M outside it, and at least ``low`` above its top. The way is the
    straight line, or with ``arc`` the arc round the loader's base (angle, reach and height
    changing evenly): the way its joints go, turning joint 1, when both ends lie at about the
    same reach. The straight line between two such points passes nearer the base, and the
    joints that set the reach pull in to the crossing and out again."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    y = lay.belt_y - math.copysign(lay.belt_width / 2 + EDGE_CLEARANCE_M, lay.belt_y - b[1])
    if arc:
        base = np.array(lay.loader_base[:2], float)
        (ra, ta), (rb, tb) = (polar(p[:2] - base) for p in (a, b))
        tb = ta + math.remainder(tb - ta, 2 * math.pi)
        f = crossing(lambda f: base[1] + (ra + f * (rb - ra)) * math.sin(
            ta + f * (tb - ta)) - y)
        r, t = ra + f * (rb - ra), ta + f * (tb - ta)
        p = np.array([base[0] + r * math.cos(t), y, a[2] + f * (b[2] - a[2])])
    else:
        f = (a[1] - y) / (a[1] - b[1]) if abs(a[1] - b[1]) > 1e-9 else 0.0
        p = a + min(max(f, 0.0), 1.0) * (b - a)
    p[1], p[2] = y, max(p[2], lay.belt_top + low)
    return p


def over_the_belt(lay: CellLayout, q_a: np.ndarray, q_b: np.ndarray, held: float) -> bool:
    """Whether the loader's joints going straight from ``q_a`` to ``q_b`` bring what its cup
    holds (``held``: its size; 0 for the empty cup) over the belt lower than SWING_CLEARANCE_M
    above the tallest material that rides on it. (From the stop to a ground place 2 cm further
    out than the paper's, the way from the edge bulged 13 cm back out over the belt, 5 cm above
    its top, and a 0.49 kg purple struck what rode there.)"""
    cup = tool_positions(lay, q_a, q_b)
    half = lay.belt_width / 2 + held / 2
    low = lay.belt_top + lay.material_size + SWING_CLEARANCE_M
    return bool(np.any((np.abs(cup[:, 1] - lay.belt_y) < half) & (cup[:, 0] < lay.belt_end_x)
                       & (cup[:, 2] - held < low)))


def lift_line(on: np.ndarray, lift: np.ndarray) -> List[np.ndarray]:
    """The points strictly between ``on`` (the cup on the material) and ``lift`` on the
    straight line up, LIFT_LINE_STEP_M apart at most (none for a rise shorter than that)."""
    on, lift = np.asarray(on, float), np.asarray(lift, float)
    rise = float(np.linalg.norm(lift - on))
    steps = max(1, int(math.ceil(rise / LIFT_LINE_STEP_M - 1e-9)))
    return [on + (lift - on) * k / steps for k in range(1, steps)]


def place_points(target: Vector, size: float, timing: PickTiming, set_down_rise: float,
                 belt_top: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cup's points over a place whose top centre is ``target``, for a material of edge
    ``size``: where it lets go (the material ``place_gap`` over the place), above that (by
    ``place_height``, or ``set_down_rise`` to clear what is there already), and the transfer
    point it rises to from there when it goes home or waits: clear of the belt (a joint-space
    move straight from there to a place lower than the belt would sweep the held material
    through the belt's side)."""
    release = np.asarray(target, float) + np.array([0.0, 0.0, size + timing.place_gap])
    above = release + np.array([0.0, 0.0, max(timing.place_height, set_down_rise)])
    transfer = release.copy()
    transfer[2] = max(above[2], belt_top + 2 * size + timing.lift_height)
    return release, above, transfer


def sweeps_into(lay: CellLayout, qs: Sequence[np.ndarray], neighbours: Sequence[Tuple[Vector,
                float]], held: float, from_height: Optional[float] = None,
                clearance: float = NEIGHBOUR_CLEARANCE_M) -> bool:
    """Whether what the loader's cup holds (a cube of edge ``held``, the cup on its top) comes
    nearer than ``clearance`` to one of ``neighbours`` (each a material's bottom
    centre in the world, and its edge) as the joints go through ``qs`` (joint-linear between
    them, SWEEP_SUBSTEPS points each), from the last point where the cup is ``from_height`` or
    higher on (the way in to the place: not the rise from the last place, which begins on a
    neighbour's top). A motion planned through a point above its place without
    stopping there (the time-optimal planner blends through it) comes down onto its slot on a
    curve: coming in from the side, a 7-joint arm's overshot 1.1 cm past its slot's column and
    pushed the material beside it 8 cm across the youBot's plate."""
    if not neighbours or len(qs) == 0:
        return False
    cups = _swept(lay, qs)
    if from_height is not None:
        high = np.nonzero(cups[:, 2] >= from_height)[0]
        cups = cups[int(high[-1]):] if len(high) else cups
    for centre, size in neighbours:
        c = np.asarray(centre, float)
        reach = (held + size) / 2 + clearance
        near = ((np.abs(cups[:, 0] - c[0]) < reach) & (np.abs(cups[:, 1] - c[1]) < reach)
                & (cups[:, 2] - held < c[2] + size + clearance))
        if bool(np.any(near)):
            return True
    return False


def _swept(lay: CellLayout, qs: Sequence[np.ndarray]) -> np.ndarray:
    """Where the loader's tool passes as its joints go through ``qs`` (joint-linear between
    them, SWEEP_SUBSTEPS points each)."""
    dense = [np.asarray(qs[0], float)]
    for a, b in zip(qs, qs[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        dense += [a + (b - a) * k / SWEEP_SUBSTEPS for k in range(1, SWEEP_SUBSTEPS + 1)]
    return tool_points(lay, dense)


def end_stop_box(lay: CellLayout) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """The belt's end stop (its lowest and highest corners in the world), None without one."""
    if not lay.end_stop:
        return None
    half = lay.belt_width / 2
    return (np.array([lay.belt_end_x, lay.belt_y - half, lay.belt_top]),
            np.array([lay.belt_end_x + END_STOP_THICKNESS_M, lay.belt_y + half,
                      lay.belt_top + END_STOP_HEIGHT_M]))


def tallest_on_belt(lay: CellLayout) -> float:
    """How high above the belt's top the tallest thing on it or at its end reaches [m]: its
    largest material, or its end stop."""
    return max(lay.material_size, END_STOP_HEIGHT_M if lay.end_stop else 0.0)


def sweeps_into_box(lay: CellLayout, qs: Sequence[np.ndarray], box: Tuple[Vector, Vector],
                    held: float, clearance: float) -> bool:
    """Whether what the loader's cup holds (a cube of edge ``held``, the cup on its top) comes
    within ``clearance`` below the top of the box (its lowest and highest corners, world
    axes) while over it, as the joints go through ``qs`` (joint-linear between them). Beside
    the box counts as clear, however near: a material lifted from against the end stop's
    face rises along it."""
    if len(qs) == 0:
        return False
    cups = _swept(lay, qs)
    lo, hi = (np.asarray(c, float) for c in box)
    half = held / 2 - TOUCHING_M
    near = ((cups[:, 0] + half > lo[0]) & (cups[:, 0] - half < hi[0])
            & (cups[:, 1] + half > lo[1]) & (cups[:, 1] - half < hi[1])
            & (cups[:, 2] - held - clearance < hi[2]) & (cups[:, 2] > lo[2]))
    return bool(np.any(near))


def from_waypoint(motion: Sequence[Tuple[float, np.ndarray, Any, Any]], q: np.ndarray,
                  after: float) -> List[Tuple[float, np.ndarray, Any, Any]]:
    """A planned motion's samples (time, joints, ...) from where it is at ``q`` (one of its
    waypoints: sampled exactly) after time ``after`` on; without such a sample, from
    ``after`` on."""
    at = next((k for k, p in enumerate(motion) if p[0] >= after
               and np.allclose(p[1], q, atol=1e-9)), None)
    return list(motion[at:]) if at is not None else [p for p in motion if p[0] >= after]
