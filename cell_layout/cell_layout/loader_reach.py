"""What the loader must reach, asked of its model at start-up (no ROS): the belt's pick window
(from the belt's end upstream, as far as the arm reaches a material there: on it, and over it
to the hover and the lift), and the youBot's plate at the loading pose. Any arm: the model is
the layout's (cell_layout/arm_models.py). A place it cannot reach refuses the world in one
line naming the place; the destinations it sets materials on are checked slot by slot
(world_layout.py)."""
from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout, LayoutError, slot_in_world
from cell_layout.link_clearance import clear_branch
from cell_layout.pick_geometry import CELL_TIMING, place_points
from cell_layout.reach import loader_descends, loader_misses, loader_reaches, loader_solution

# Along the belt's centre line, every this far [m].
WINDOW_STEP_M = 0.02
# A material may lie this far off the belt's centre line (the source's lateral jitter, and
# more) [m].
LATERAL_M = 0.03
# The shortest window the loader meets materials in on the move [m].
MIN_WINDOW_M = 0.15
# Following a material: a tool moving this fast (along the belt, or up: a pick's descent and
# lift) takes at most this share of each joint's speed limit [m/s] (the rest: the planner's
# acceleration; a pick descends at up to 0.33 m/s, and a belt in a study runs at 0.3 m/s),
# measured over this step [m].
FOLLOW_SPEED_M_S = 0.35
FOLLOW_SHARE = 0.8
FOLLOW_STEP_M = 0.005


def pick_points(layout: CellLayout, x: float) -> List[np.ndarray]:
    """The world points the loader's tool passes through picking a material at ``x``: on it,
    lifted over it, and hovering where the material was when the descent began (upstream by
    its travel over the descent, at the fastest belt the cell follows)."""
    top = layout.belt_top + layout.material_size
    lead = FOLLOW_SPEED_M_S * CELL_TIMING.descend
    # (along, up): on it, the hover, the lift
    offsets = ((0.0, 0.0), (-lead, CELL_TIMING.hover), (0.0, CELL_TIMING.lift_height))
    return [np.array([x + along, layout.belt_y + dy, top + up])
            for dy in (-LATERAL_M, 0.0, LATERAL_M) for along, up in offsets]


# Each loader's pick window and plate check, by what they depend on: a cell's layout is read
# by every node and tool, many times in a study (the scan takes a quarter of a second).
_WINDOWS: Dict[Tuple[object, ...], float] = {}
_PLATES: Dict[Tuple[object, ...], Tuple[Tuple[float, float], ...]] = {}
_MEMO_MAX = 256


def pick_window(layout: CellLayout) -> float:
    """pick_window_of, remembered for the loader and the belt (a refusal is not)."""
    key = (layout.loader, layout.loader_base, layout.belt_y, layout.belt_top,
           layout.belt_end_x, layout.belt_start_x, layout.material_size)
    if key not in _WINDOWS:
        if len(_WINDOWS) >= _MEMO_MAX:
            _WINDOWS.clear()
        _WINDOWS[key] = pick_window_of(layout)
    return _WINDOWS[key]


def pick_window_of(layout: CellLayout) -> float:
    """The most upstream belt x from which the loader meets every material downstream to the
    belt's end: it reaches it, and follows it there (a tool moving at FOLLOW_SPEED_M_S along
    the belt or up) within FOLLOW_SHARE of its joints' speed limits. Near the edge of its
    reach an arm is stretched out, and following a material needs joint speeds past its limits
    (a Panda's first joint 5.8 rad/s at 1.9 m/s allowed, met 3 cm inside it). A LayoutError if
    it does not meet one at the belt's end, or meets them along less than MIN_WINDOW_M."""
    end = layout.belt_end_x - layout.material_size / 2
    start = layout.belt_start_x + layout.material_size / 2
    seed = None
    x = end + WINDOW_STEP_M
    while x - WINDOW_STEP_M >= start - 1e-9:
        why, seed = _meets(layout, x - WINDOW_STEP_M, seed)
        if why:
            if x > end:
                raise LayoutError(f'the loader {layout.loader.name} does not meet a material '
                                  f'at the belt\'s end (x = {end:.3f} m): {why}')
            break
        x -= WINDOW_STEP_M
    if end - x < MIN_WINDOW_M - 1e-9:
        raise LayoutError(f'the loader {layout.loader.name} meets materials along '
                          f'{end - x:.2f} m of the belt (x = {x:.3f} to {end:.3f} m), less '
                          f'than the {MIN_WINDOW_M} m it needs to pick them on the move')
    return float(x)


def _meets(layout: CellLayout, x: float, seed: Optional[np.ndarray]
           ) -> Tuple[str, Optional[np.ndarray]]:
    """Why the loader does not meet a material at ``x`` ('' if it does), and its joints on
    the material's top there (the next x's seed)."""
    missed = loader_misses(layout, pick_points(layout, x))
    if missed:
        return (f'it does not reach {np.round(missed[0], 3).tolist()} with its tool pointing '
                'down'), seed
    model = layout.loader.model
    on = np.array([x, layout.belt_y, layout.belt_top + layout.material_size])
    q = loader_solution(layout, on, seed)
    if q is None:
        return 'no IK solution on the material', seed
    limits = np.asarray(model.velocity)
    for direction in ((FOLLOW_STEP_M, 0.0, 0.0), (0.0, 0.0, FOLLOW_STEP_M)):
        q2 = loader_solution(layout, on + np.array(direction), q)
        if q2 is None:
            return 'no IK solution beside the material', seed
        speeds = np.abs(q2 - q) / FOLLOW_STEP_M * FOLLOW_SPEED_M_S
        k = int(np.argmax(speeds / limits))
        if speeds[k] > FOLLOW_SHARE * limits[k]:
            return (f'following it at {FOLLOW_SPEED_M_S} m/s takes {model.spec.joints[k]} '
                    f'{speeds[k]:.2f} rad/s, above {FOLLOW_SHARE:.0%} of its '
                    f'{limits[k]:.2f}'), seed
    return '', q


def clear_plate_slots(layout: CellLayout) -> Tuple[Tuple[float, float], ...]:
    """clear_plate_slots_of, remembered for the loader, the loading pose, the plate's slots and
    what the links are checked against (a refusal is not)."""
    carried = max((r.size for r in layout.rules.values() if r.route == 'carry'), default=0.0)
    key = (layout.loader, layout.loader_base, layout.youbot_home, layout.youbot_base_z,
           layout.plate_slots, carried, layout.belt_top, layout.transport.arm, layout.fixed,
           layout.link_clearance, layout.belt_y, layout.belt_end_x, layout.belt_start_x,
           layout.belt_width, layout.end_stop)
    if key not in _PLATES:
        if len(_PLATES) >= _MEMO_MAX:
            _PLATES.clear()
        _PLATES[key] = clear_plate_slots_of(layout)
    return _PLATES[key]


def clear_plate_slots_of(layout: CellLayout) -> Tuple[Tuple[float, float], ...]:
    """The plate's slots the loader fills with a carried material at the loading pose (the
    first youBot's home), its links keeping clear on the way down on some branch of its IK
    (link_clearance.clear_branch; the others are left out: an xArm 6's upper arm struck the
    conveyor lowering onto the plate's far corner). A LayoutError unless it reaches each slot
    (where it lets go, above that, and the transfer point it swings in and out through:
    pick_geometry.place_points), or where its links strike something over every slot."""
    carried = [r.size for r in layout.rules.values() if r.route == 'carry']
    if not carried:
        return layout.plate_slots
    size, clear, struck = max(carried), [], ''
    home = layout.loader.model.spec.preferred
    for k, slot in enumerate(layout.plate_slots):
        points = place_points(slot_in_world(layout.youbot_home, slot, layout.youbot_base_z, size),
                              size, CELL_TIMING, 0.0, layout.belt_top)
        missed = loader_misses(layout, points)
        if missed:
            raise LayoutError(f'the loader {layout.loader.name} does not reach the youBot\'s '
                              f'plate at the loading pose: slot {k} at '
                              f'{np.round(missed[0], 3).tolist()} with its tool pointing down')
        qs, hit = clear_branch(layout, points[::-1], None if home is None else np.array(home))
        if qs is None:
            struck = struck or f'slot {k}: its {hit}'
        else:
            clear.append(slot)
    if not clear:
        raise LayoutError(f'the loader {layout.loader.name} sets nothing onto the youBot\'s '
                          f'plate at the loading pose with its links clear on any IK branch '
                          f'({struck})')
    return tuple(clear)


def with_pick_window(layout: CellLayout) -> CellLayout:
    """The layout with its pick window, and the plate's slots the loader fills (checked
    against the loader's reach and its links)."""
    return replace(layout, plate_slots=clear_plate_slots(layout), pick_from=pick_window(layout))


# The straight descent onto a place is checked from this far over it [m].
PLACE_RISE_M = 0.15


def loader_place_slots(layout: CellLayout, name: str, slots: Sequence[np.ndarray], size: float
                       ) -> Tuple[np.ndarray, ...]:
    """Those of destination ``name``'s slots (surface points) the loader serves with a material
    of edge ``size``: it reaches over it (and the transfer point above it) with its tool down,
    goes straight down onto it from PLACE_RISE_M without its joints jumping (a slot where a
    7-joint arm changes its posture on the way down is left out), and its links keep clear on
    the way down on some branch of its IK (link_clearance.clear_branch). A LayoutError where it
    serves none, saying why."""
    lift, served, struck = size + 0.01, [], ''
    home = layout.loader.model.spec.preferred
    for p in slots:
        points = place_points(p, size, CELL_TIMING, 0.0, layout.belt_top)
        if not (loader_reaches(layout, [p + np.array([0.0, 0.0, lift]),
                                        p + np.array([0.0, 0.0, lift + 0.07]), points[2]])
                and loader_descends(layout, p + np.array([0.0, 0.0, lift]), PLACE_RISE_M)):
            continue
        qs, hit = clear_branch(layout, points[::-1], None if home is None else np.array(home))
        if qs is None:
            struck = struck or hit
        else:
            served.append(p)
    if not served:
        raise LayoutError(
            f'destination {name} is out of the reach of the loader {layout.loader.name} ('
            + (f'its {struck} over each slot it reaches, on every IK branch)' if struck else
               f'its base at {layout.loader_base[:2]}, the tool pointing down)'))
    return tuple(served)
