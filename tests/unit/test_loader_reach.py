"""What the loader must reach, asked of its model at start-up, whatever the arm (issue 64): the
belt's pick window, the youBot's plate and the transfer points, the straight descent onto a
place; and the check that keeps what the cup holds off the materials beside its place."""
import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from cell_layout.layout import LayoutError, slot_in_world
from cell_layout.pick_geometry import CELL_TIMING, place_points, sweeps_into
from cell_layout.reach import loader_descends, loader_solution
from cell_layout.world_layout import layout_from_world
from world_description.world_config import load_world
from world_description.world_loading import world_data
from world_description.world_sections import parse_world

WORLDS = Path(__file__).resolve().parents[2] / 'world_description' / 'worlds'


def _layout(name):
    return layout_from_world(load_world(WORLDS / name))


def test_the_pick_window_is_where_the_loader_follows_a_material():
    """The Zu 12 reaches the belt from well upstream of the paper's pick point (so it picks
    there, as before); the Panda only from x = -0.005 m, where following a material at
    0.35 m/s takes its joints at most 80 % of their speed limits and it reaches the hover point
    its descent begins from (upstream by the material's travel at 0.35 m/s). (Before the IK
    settled each solution fully, the speeds between two solutions 5 mm apart were noisy: at
    0.05 m a joint seemed to need 1.60 rad/s.)"""
    assert _layout('pipeline_cell.yaml').pick_from < -0.6
    panda = _layout('cell_panda.yaml')
    assert -0.1 < panda.pick_from < 0.1
    end = panda.belt_end_x - panda.material_size / 2
    assert end - panda.pick_from > 0.4


def _moved(name, x, y):
    data = copy.deepcopy(world_data(WORLDS / name))
    data['robots'][0]['pose'].update(x=x, y=y)
    return parse_world(yaml.safe_load(yaml.safe_dump(data)), str(WORLDS / name))


@pytest.mark.parametrize('x, y, fragment', [
    # Too far from the belt: refused at its end, with the point it does not reach.
    (0.45, 0.1, r"the loader panda does not meet a material at the belt's end \(x = 0.675 m\): "
                r"it does not reach \[0.675, 0.75, 0.52\] with its tool pointing down"),
    # Its base column beside the target's stand: on every branch of its IK its first link is
    # inside the stand (the link check, with the arm's collision model).
    (0.45, 0.0, r'destination ground_target is out of the reach of the loader panda \(its '
                r'panda_link1 on the purple_stand over each slot it reaches, on every IK '
                r'branch\)'),
    # Far from everything: the first place found out of its reach.
    (-0.9, 0.2, r'destination ground_target is out of the reach of the loader panda \(its base '
                r'at \(-0.9, 0.2\)'),
    # Beside the belt but short of the plate at the loading pose.
    (0.0, 0.35, r"the loader panda does not reach the youBot's plate at the loading pose: slot "
                r"\d at \["),
])
def test_a_loader_that_cannot_serve_a_place_is_refused_naming_it(x, y, fragment):
    with pytest.raises(LayoutError, match=fragment):
        layout_from_world(_moved('cell_panda.yaml', x, y))


def test_the_places_slots_are_those_the_loader_goes_straight_down_onto():
    panda = _layout('cell_panda.yaml')
    target = panda.regions['ground_target']
    assert target.slots
    for slot in target.slots:
        bottom = np.asarray(slot) + np.array([0.0, 0.0, 0.06])
        assert loader_descends(panda, bottom, 0.15)
        assert loader_solution(panda, place_points(slot, 0.05, CELL_TIMING, 0.0,
                                                   panda.belt_top)[2]) is not None


def test_a_held_material_sweeping_into_a_neighbour_is_seen():
    """Joints whose cup comes down beside a plate slot taken by another material sweep into
    it; the same motion onto a slot with nothing beside it does not; a way that stays high
    does not either."""
    lay = _layout('cell_panda.yaml')
    size = 0.05
    near = slot_in_world(lay.youbot_home, lay.plate_slots[0], lay.youbot_base_z, size)
    beside = slot_in_world(lay.youbot_home, lay.plate_slots[2], lay.youbot_base_z, size)
    above = beside + np.array([0.0, 0.0, size + 0.1])
    # Down on a curve: through a point over the neighbour's edge, low.
    inward = beside + (near - beside) * 0.45 + np.array([0.0, 0.0, size + 0.01])
    release = beside + np.array([0.0, 0.0, size + 0.003])
    qs = []
    seed = None
    for p in (above, inward, release):
        seed = loader_solution(lay, p, seed)
        qs.append(seed)
    neighbour = [(near, size)]
    assert sweeps_into(lay, qs, neighbour, size)
    assert not sweeps_into(lay, qs, [], size)
    straight = [loader_solution(lay, above), loader_solution(lay, release, qs[0])]
    assert not sweeps_into(lay, straight, neighbour, size)
    # The rise from the last place (on the neighbour's top) is not the way in to this one.
    rise = [loader_solution(lay, near + np.array([0.0, 0.0, size + 0.003])),
            loader_solution(lay, near + np.array([0.0, 0.0, size + 0.1]))]
    assert sweeps_into(lay, rise + straight, neighbour, size)
    assert not sweeps_into(lay, rise + straight, neighbour, size, from_height=above[2] - 0.005)
