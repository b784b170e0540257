"""The loader's links against the cell's fixed things (cell_layout/link_clearance.py, issue 64):
the conveyor as the simulator builds it and the world's boxes, by the arm's collision model
from its URDF, whatever the arm."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cell_layout.layout import LayoutError, slot_in_world
from cell_layout.lift_swing import near_on_belt
from cell_layout.link_clearance import (
    clear_branch,
    conveyor_boxes,
    link_clearance,
    other_branch,
    transport_solids,
    way_strikes,
)
from cell_layout.loader_reach import clear_plate_slots_of
from cell_layout.pick_geometry import CELL_TIMING, place_points
from cell_layout.reach import loader_solution
from cell_layout.world_layout import layout_from_world
from world_description.world_config import load_world

WORLDS = Path(__file__).resolve().parents[2] / 'world_description' / 'worlds'


def _layout(name):
    return layout_from_world(load_world(WORLDS / name))


@pytest.mark.parametrize('world, touching', [('pipeline_cell.yaml', 'suction_tool'),
                                             ('cell_panda.yaml', 'panda_')])
def test_a_link_pressed_into_the_belt_is_told_and_one_on_a_material_is_clear(world, touching):
    lay = _layout(world)
    check = link_clearance(lay)
    assert check is not None
    x = lay.belt_end_x - 0.3            # (within both loaders' pick windows, off the stop)
    on = np.array([x, lay.belt_y, lay.belt_top + lay.material_size])
    q_on = loader_solution(lay, on, None)
    assert check.strikes([q_on]) == ''
    q_in = loader_solution(lay, on - np.array([0.0, 0.0, 0.12]), q_on)
    hit = check.strikes([q_on, q_in])
    assert hit.startswith(touching) and hit.endswith('on the conveyor belt'), hit
    # A swing whose samples pass through it is near something, by name.
    assert near_on_belt(lay, [(0.0, q_on, None, None), (0.1, q_in, None, None)], 0.05,
                        []) == hit


def test_the_conveyor_is_the_simulators_and_the_worlds_boxes_are_checked_too():
    lay = _layout('cell_panda.yaml')
    names = [b[0] for b in conveyor_boxes(lay)]
    assert names == ['conveyor belt', 'conveyor stand', 'end stop']
    belt = conveyor_boxes(lay)[0]
    assert belt[1][2] + belt[2][2] == pytest.approx(lay.belt_top)
    assert 'purple_stand' in [f[0] for f in lay.fixed]
    # A cell that asks no check has none.
    assert link_clearance(replace(lay, link_clearance=-1.0)) is None


def _solved(lay, points, seed):
    """The loader's joints at each of ``points``, each from the one before."""
    qs = []
    for p in points:
        qs.append(loader_solution(lay, p, qs[-1] if qs else seed))
        assert qs[-1] is not None
    return qs


def _link_in_world(lay, check, q, link):
    """Where ``link``'s collision geometry is in the world with the loader at ``q``."""
    qq = np.zeros(check.model.nq)
    qq[check._index] = q
    pin.updateGeometryPlacements(check.model, check.data, check.geometry, check.geometry_data,
                                 qq)
    k = next(k for k, g in enumerate(check.geometry.geometryObjects) if g.name.startswith(link))
    x, y, z, yaw = lay.loader_base
    base = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, yaw), np.array([x, y, z]))
    return (base * check.geometry_data.oMg[k]).translation


def test_the_youbot_waiting_to_be_loaded_is_among_what_the_links_keep_clear_of():
    """The first transport at the loading pose, its arm upright in its carry posture: the
    loader's tool lowered onto its arm strikes it, by the youBot's link's name (an iiwa's
    forearm had struck a youBot's arm on the way onto its plate)."""
    lay = _layout('pipeline_cell.yaml')
    solids = {name: where for name, where, _ in transport_solids(lay)}
    assert {"youbot's base_link", "youbot's plate_link", "youbot's arm_link_3"} <= set(solids)
    top = solids["youbot's gripper_palm_link"].translation
    q = loader_solution(lay, top + np.array([0.0, 0.0, 0.03]), None)
    assert q is not None
    hit = link_clearance(lay).strikes([q])
    assert "on the youbot's" in hit, hit
    # Placing onto the plate, clear of it.
    slot = slot_in_world(lay.youbot_home, lay.plate_slots[0], lay.youbot_base_z,
                         lay.material_size)
    points = place_points(slot, lay.material_size, CELL_TIMING, 0.0, lay.belt_top)[::-1]
    assert way_strikes(lay, _solved(lay, points, None)) == ''


def test_a_place_whose_links_strike_something_is_served_on_another_branch_of_its_ik():
    """A post beside the Zu 12's elbow over the ground target: the way down on its home's
    branch strikes it; another branch of its IK keeps clear, and the place is served there."""
    lay = _layout('pipeline_cell.yaml')
    home = np.array(lay.loader.model.spec.preferred)
    slot = lay.regions['ground_target'].slots[0]
    points = place_points(slot, lay.material_size, CELL_TIMING, 0.0, lay.belt_top)[::-1]
    qs = _solved(lay, points, home)
    assert way_strikes(lay, qs) == '' and other_branch(lay, points, qs) is None
    elbow = _link_in_world(lay, link_clearance(lay), qs[1], 'link_3')
    posted = replace(lay, fixed=lay.fixed + (('post', tuple(elbow), (0.03, 0.03, 0.03), 0.0),))
    assert way_strikes(posted, qs) == 'link_3 on the post'
    clear, why = clear_branch(posted, points, home)
    assert clear is not None and why == ''
    assert way_strikes(posted, clear) == ''
    assert float(np.max(np.abs(clear[1] - qs[1]))) > 0.5       # (another branch)
    other = other_branch(posted, points, qs)
    assert other is not None and np.allclose(other, clear[0])


def test_plate_slots_whose_way_down_strikes_on_every_branch_are_left_out():
    """A post just over one slot's transfer point (the cup itself passes through it on every
    branch): that slot is left out, the others kept; posts over every slot refuse the cell in
    one line naming the first slot and what struck what."""
    lay = _layout('pipeline_cell.yaml')
    size = lay.material_size

    def post(k):
        transfer = place_points(slot_in_world(lay.youbot_home, lay.plate_slots[k],
                                              lay.youbot_base_z, size), size, CELL_TIMING,
                                0.0, lay.belt_top)[2]
        return (f'post {k}', tuple(transfer), (0.005, 0.005, 0.005), 0.0)

    assert clear_plate_slots_of(lay) == lay.plate_slots
    last = len(lay.plate_slots) - 1
    one = replace(lay, fixed=lay.fixed + (post(last),))
    assert clear_plate_slots_of(one) == lay.plate_slots[:last]
    every = replace(lay, fixed=lay.fixed + tuple(post(k) for k in range(last + 1)))
    with pytest.raises(LayoutError, match=r"sets nothing onto the youBot's plate at the "
                                          r"loading pose .*\(slot 0: its .* on the post 0\)"):
        clear_plate_slots_of(every)
