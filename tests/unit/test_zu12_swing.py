"""The Zu 12's swings between the belt and a place lower than the belt keep what its cup holds
(and the empty cup) above what rides on the belt (real Zu 12 IK and forward kinematics). From
the end stop to a ground slot 7 cm further out than the paper's, the joints' way from the belt's
edge down to above the slot bulged 13 cm back out over the belt, 5 cm above its top, and a
0.49 kg purple struck the materials riding there (the arm stalled, the purple fell on the
belt)."""
import copy

import numpy as np
import pytest
from test_cell_rules import world
from test_material_classes import PAPER_CLASSES as PAPER
from test_pipeline import Zu12IK

from cell_layout import pick_geometry
from cell_layout.pick_geometry import edge_point, over_the_belt
from cell_layout.world_layout import layout_from_world
from controllers.time_optimal import Waypoint
from coordinator.pipeline import Material, Pipeline, Settings, model

READY = np.array([1.201, 1.436, -1.222, 1.357, 1.571, -0.37])      # (the world's)


def _cell(size, count):
    classes = copy.deepcopy(PAPER)
    classes['purple'].update(count=count, size=size)
    layout = layout_from_world(world(classes))
    run_ = Pipeline(layout, Zu12IK(), Settings())
    return layout, run_, run_.loader


@pytest.mark.parametrize('size,count', [(0.05, 1), (0.047, 3), (0.06, 4)])
def test_the_way_onto_a_ground_slot_keeps_the_held_material_over_what_rides_on_the_belt(
        size, count, monkeypatch):
    layout, run_, zu12 = _cell(size, count)
    m = Material(1, 'purple', np.zeros(3), 0.0, 3, size=size)
    lift = np.array([layout.belt_end_x - size / 2, layout.belt_y,
                     layout.belt_top + size + 0.07])
    through = 0
    for k in range(len(layout.regions['ground_target'].slots)):
        zu12.planner.room.free_places = lambda name, material, k=k: [k]
        way = zu12.planner.place_way(m, lift, layout.youbot_home, READY)
        qs = [w.q for w in way.waypoints]
        through += len(qs) == 4                     # (edge, transfer, above, release)
        # From the edge on (the lift point is over the belt by design): what the cup holds
        # never comes down among what rides on the belt.
        with monkeypatch.context() as patch:
            patch.setattr(pick_geometry, 'SWING_CLEARANCE_M', 0.0)
            assert not any(over_the_belt(layout, a, b, size) for a, b in zip(qs, qs[1:])), k
        # Without the transfer point, some ways do.
        if len(qs) == 4:
            assert over_the_belt(layout, qs[0], qs[2], size)
    assert through > 0


def test_the_way_back_from_a_low_place_rises_over_it_before_it_swings_to_the_belt():
    """The empty cup's way back from a low place to the belt's edge (on to a pick) goes up over
    the place first where the straight swing would bulge out over the belt, low: from a
    second ground target nearer the Zu 12, back to a pick downstream."""
    classes = copy.deepcopy(PAPER)
    classes['green'] = {'color': [0.1, 0.8, 0.2, 1.0], 'count': 2,
                        'destination': 'green_target', 'route': 'place', 'size': 0.052}
    green = {'name': 'green_target', 'shape': 'box', 'size': [0.2, 0.2, 0.002],
             'position': [-0.55, -0.15, 0.001], 'collision': False}
    layout = layout_from_world(world(classes, obstacles=[green]))
    run_ = Pipeline(layout, Zu12IK(), Settings())
    zu12 = run_.loader
    m = Material(1, 'green', np.zeros(3), 0.0, 3, size=0.052)
    lift = np.array([layout.belt_end_x - 0.026, layout.belt_y, layout.belt_top + 0.122])
    zu12.planner.room.free_places = lambda name, material: [0]
    way = zu12.planner.place_way(m, lift, layout.youbot_home, READY)
    zu12.cup.adopt(*way.rise)
    zu12.cup.released()
    hover = np.array([0.6, layout.belt_y, layout.belt_top + 0.1])
    crossing = edge_point(layout, hover, zu12.cup.above, pick_geometry.EDGE_CLEARANCE_M)
    edge = run_.loader_arm.solve(crossing, model.DOWN, 'world', zu12.cup.above_q)
    assert over_the_belt(layout, zu12.cup.above_q, edge, 0.0)
    waypoints, _ = zu12.cup.from_release([Waypoint(edge)], edge)
    qs = [w.q for w in waypoints]
    assert np.allclose(qs[1], way.then)             # up over the place first
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pick_geometry, 'SWING_CLEARANCE_M', 0.0)
        assert not any(over_the_belt(layout, a, b, 0.0) for a, b in zip(qs, qs[1:]))
