"""What the loader must reach, asked of its model at start-up (no ROS): the belt's pick window
(from the belt's end upstream, as far as the arm reaches a material there: on it, and over it
to the hover and the lift), and the youBot's plate at the loading pose. Any arm: the model is
the layout's (cell_layout/arm_models.py). A place it cannot reach refuses the world in one
line naming the place; the destinations it sets materials on are checked slot by slot
(world_layout.py)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from cell_layout.layout import CellLayout, LayoutError, slot_in_world
from cell_layout.reach import loader_misses

# Along the belt's centre line, every this far [m].
WINDOW_STEP_M = 0.02
# The tool's heights over a material's top the pick passes through [m]: on it, the hover
# (PickTiming.hover), the lift (PickTiming.lift_height over the belt, a 50 mm material).
PICK_HEIGHTS_M = (0.0, 0.10)
LIFT_OVER_BELT_M = 0.15
# A material may lie this far off the belt's centre line (the source's lateral jitter, and
# more) [m].
LATERAL_M = 0.03
# The shortest window the loader meets materials in on the move [m].
MIN_WINDOW_M = 0.15
# A carried material over a plate slot: its bottom, and the straight descent's top [m].
PLACE_HEIGHTS_M = (0.003, 0.15)


def pick_points(layout: CellLayout, x: float) -> list:
    """The world points the loader's tool passes through picking a material at ``x``."""
    top = layout.belt_top + layout.material_size
    lift = layout.belt_top + max(LIFT_OVER_BELT_M, 2 * layout.material_size)
    return [np.array([x, layout.belt_y + dy, z]) for dy in (-LATERAL_M, 0.0, LATERAL_M)
            for z in (*(top + h for h in PICK_HEIGHTS_M), lift)]


def pick_window(layout: CellLayout) -> float:
    """The most upstream belt x from which the loader reaches every material downstream to
    the belt's end; a LayoutError if it does not reach the end, or reaches less than
    MIN_WINDOW_M of the belt."""
    end = layout.belt_end_x - layout.material_size / 2
    start = layout.belt_start_x + layout.material_size / 2
    missed = loader_misses(layout, pick_points(layout, end))
    if missed:
        raise LayoutError(f'the loader {layout.loader.name} does not reach the belt\'s end '
                          f'(a material at x = {end:.3f} m: {np.round(missed[0], 3).tolist()} '
                          'with its tool pointing down)')
    x = end
    while x - WINDOW_STEP_M >= start and not loader_misses(layout, pick_points(
            layout, x - WINDOW_STEP_M)):
        x -= WINDOW_STEP_M
    if end - x < MIN_WINDOW_M - 1e-9:
        raise LayoutError(f'the loader {layout.loader.name} reaches {end - x:.2f} m of the belt '
                          f'(x = {x:.3f} to {end:.3f} m), less than the {MIN_WINDOW_M} m it '
                          'meets materials in on the move')
    return float(x)


def check_plate(layout: CellLayout) -> None:
    """A LayoutError unless the loader reaches each of the plate's slots it fills with a
    carried material, at the loading pose (the first youBot's home)."""
    carried = [r.size for r in layout.rules.values() if r.route == 'carry']
    if not carried:
        return
    size = max(carried)
    for k, slot in enumerate(layout.plate_slots):
        base = slot_in_world(layout.youbot_home, slot, layout.youbot_base_z, size)
        points = [base + np.array([0.0, 0.0, size + h]) for h in PLACE_HEIGHTS_M]
        missed = loader_misses(layout, points)
        if missed:
            raise LayoutError(f'the loader {layout.loader.name} does not reach the youBot\'s '
                              f'plate at the loading pose: slot {k} at '
                              f'{np.round(missed[0], 3).tolist()} with its tool pointing down')


def with_pick_window(layout: CellLayout) -> CellLayout:
    """The layout with its pick window and the plate checked against the loader's reach."""
    check_plate(layout)
    return replace(layout, pick_from=pick_window(layout))
