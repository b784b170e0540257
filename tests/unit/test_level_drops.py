"""A pool material is let go level, as it lay on the plate, wherever a free drop spot allows it.
The youBot's five joints lean its tool only in the arm's plane: a material gripped at one tilt
and let go at another falls tilted by the difference. Let go 14 cm over the pool tilted 30-40
degrees, cubes landed on an edge, drifted up to 6 cm and came to rest on a neighbour (held-back
trials of 19 oranges); let go level, they land flat where they were let go."""
import copy
import math

import numpy as np
import pytest
from test_cell_rules import world
from test_material_classes import PAPER_CLASSES as PAPER
from test_pipeline import _YoubotIK

from cell_layout.layout import YOUBOT_CARRY_Q, world_to_base
from cell_layout.reach import _youbot_solutions, youbot_holds
from cell_layout.unload_geometry import grip_points
from cell_layout.world_layout import layout_from_world
from coordinator.pipeline import Material, Pipeline, Settings
from coordinator.pipeline.unload_planner import SLIDE_MIN_M


def tool_tilt(kin, q) -> float:
    """How far the youBot's tool leans from straight down at joints ``q`` [deg]."""
    z = kin.fk(q)[:3, 2]
    return math.degrees(math.acos(float(np.clip(-z[2], -1.0, 1.0))))


def tilts(points, mass, held_from=0):
    """The tilts (of 0, 10, ... 80 degrees) at which the arm reaches every point (base_link)
    and holds ``mass`` kg at rest from ``held_from`` on."""
    found = set()
    for tilt in range(0, 90, 10):
        qs = _youbot_solutions(points, tilt)
        if qs is not None and youbot_holds(qs[held_from:], mass):
            found.add(tilt)
    return found


def level_way_exists(layout, planner, m, stand, mass) -> bool:
    """Whether some free drop of ``stand`` is reached at a tilt that ``m``'s grip is, from the
    stand or from the base slid abeam it (computed here from the arm's kinematics, spot by
    spot, not by the planner)."""
    contact, hover, lift = grip_points(layout.plate_slots[m.slot], m.size, 0, True, m.size)
    grip = tilts([hover, contact, *lift], mass, held_from=1)
    used = planner.book.dropped(stand.name)
    for k, point in enumerate(stand.drops):
        if k in used:
            continue
        poses = [stand.pose]
        at = stand.abeam(point)
        if math.hypot(at[0] - stand.pose[0], at[1] - stand.pose[1]) >= SLIDE_MIN_M:
            poses.append(at)
        for pose in poses:
            drop = world_to_base(pose, point)
            drop[2] -= layout.youbot_base_z
            over = drop + [0.0, 0.0, max(0.05, lift[-1][2] - drop[2])]
            if grip & tilts([over, drop], mass):
                return True
    return False


@pytest.mark.slow
def test_a_pool_material_is_let_go_level_wherever_a_free_spot_allows_it():
    """19 oranges, more than the stands' own eight spots, in three trips of full plates: each
    unload lets its material go at the tilt it gripped it at (the tool's tilt by forward
    kinematics, at the grip and at the drop) wherever a free spot, from the stand or slid
    along its line, allows that; the spot that needs the arm leant furthest is taken first,
    so that the grips far back on the plate leave the near spots to those that cannot lean
    as far, and at most one of the 19 is let go tilted."""
    classes = copy.deepcopy(PAPER)
    classes['orange'].update(count=19)
    classes['purple'].update(count=1)
    layout = layout_from_world(world(classes))
    ports = _YoubotIK()
    run_ = Pipeline(layout, ports, Settings())
    planner = run_.transport.planner
    mass = layout.rule('orange').mass
    order = layout.slot_order('orange')
    left, ident, tilted, level = 19, 0, [], 0
    while left:
        trip = order[:min(left, len(order))]
        if left < len(order):
            # (A last short load on the row whose stand has the most spots left: 10 and 11.)
            free = {st.row: len(st.drops) - len(planner.book.dropped(st.name))
                    for st in layout.stands}
            trip = [k for k in order if layout.slot_row(k) == max(free, key=free.get)][:left]
        left -= len(trip)
        run_.materials.clear()
        for k in trip:
            ident += 1
            run_.materials[ident] = Material(ident, 'orange', np.zeros(3), 0.0, 3,
                                             status='on_plate', slot=k, size=0.05)
        for m in list(run_.materials.values()):
            stand = layout.stand_for('orange', m.slot)
            possible = level_way_exists(layout, planner, m, stand, mass)
            path = planner.unload_path(m, stand.pose, YOUBOT_CARRY_Q, high=True, slide=True)
            assert path is not None, (m.id, m.slot)
            grip, drop = tool_tilt(ports.kin, path.contact), tool_tilt(ports.kin, path.drop)
            if possible:
                assert abs(grip - drop) < 0.5, (m.id, m.slot, stand.name, path.place, grip, drop)
                level += 1
            else:
                tilted.append((m.slot, path.place, round(drop - grip)))
            planner.book.unload_attempt(m, path.place)
            planner.book.delivered(m, stand.name)
            del run_.materials[m.id]
    assert level + len(tilted) == 19 and len(tilted) <= 1, tilted
