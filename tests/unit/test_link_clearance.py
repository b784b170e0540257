"""The loader's links against the cell's fixed things (cell_layout/link_clearance.py, issue 64):
the conveyor as the simulator builds it and the world's boxes, by the arm's collision model
from its URDF, whatever the arm."""
from pathlib import Path

import numpy as np
import pytest

from cell_layout.lift_swing import near_on_belt
from cell_layout.link_clearance import conveyor_boxes, link_clearance
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
    from dataclasses import replace
    assert link_clearance(replace(lay, link_clearance=-1.0)) is None
