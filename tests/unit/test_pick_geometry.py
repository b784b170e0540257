"""The Zu 12's pick and place geometry (coordinator/pipeline/pick_geometry.py), each function on
its own: the belt's edge crossing, swings over the belt, the straight lift, the points over a
place, IK branches."""
import math

import numpy as np
import pytest
from test_pipeline import Zu12IK, cell_layout
from test_zu12_swing import READY

from cell_layout.pick_geometry import (
    EDGE_CLEARANCE_M,
    IK_JUMP_RAD,
    LIFT_LINE_STEP_M,
    continuous,
    crossing,
    edge_point,
    end_stop_box,
    lift_line,
    over_the_belt,
    place_points,
    polar,
    sweeps_into_box,
    tallest_on_belt,
)
from controllers.pick_place import PickTiming
from coordinator.pipeline.model import DOWN
from world_description.world_schema import END_STOP_HEIGHT_M


def test_crossing_finds_the_first_sign_change_or_the_nearer_end():
    assert crossing(lambda f: f - 0.3) == pytest.approx(0.3, abs=1e-9)
    # Two roots: the first.
    assert crossing(lambda f: (f - 0.2) * (f - 0.7)) == pytest.approx(0.2, abs=1e-9)
    # None: the end where |g| is smaller.
    assert crossing(lambda f: 1.0 + f) == 0.0
    assert crossing(lambda f: 2.0 - f) == 1.0


def test_polar_is_reach_and_angle():
    r, t = polar(np.array([0.0, -2.0]))
    assert r == pytest.approx(2.0) and t == pytest.approx(-math.pi / 2)


def test_the_straight_way_crosses_the_near_edge_outside_the_belt_and_above_its_top():
    lay = cell_layout()
    side = 1.0 if lay.loader_base[1] > lay.belt_y else -1.0      # (the Zu 12's side)
    a = np.array([0.5, lay.belt_y, lay.belt_top + 0.01])
    b = np.array([0.3, lay.belt_y + side * 0.5, lay.belt_top + 0.2])
    p = edge_point(lay, a, b, low=0.05)
    assert p[1] == pytest.approx(lay.belt_y + side * (lay.belt_width / 2 + EDGE_CLEARANCE_M))
    f = (p[1] - a[1]) / (b[1] - a[1])
    assert p[0] == pytest.approx(a[0] + f * (b[0] - a[0]))         # on the line, in x
    assert p[2] == pytest.approx(max(a[2] + f * (b[2] - a[2]), lay.belt_top + 0.05))
    # Low ends: lifted to ``low`` over the belt's top.
    assert edge_point(lay, a, b * [1, 1, 0], low=0.08)[2] == pytest.approx(lay.belt_top + 0.08)


def test_the_arc_round_the_base_crosses_the_edge_at_a_reach_between_its_ends():
    lay = cell_layout()
    base = np.array(lay.loader_base[:2], float)
    side = 1.0 if base[1] > lay.belt_y else -1.0
    a = np.array([0.6, lay.belt_y, 0.5])
    b = np.array([base[0] + 0.2, lay.belt_y + side * 0.45, 0.55])
    p = edge_point(lay, a, b, low=0.0, arc=True)
    assert p[1] == pytest.approx(lay.belt_y + side * (lay.belt_width / 2 + EDGE_CLEARANCE_M))
    ra, rb, rp = (np.linalg.norm(np.asarray(q[:2]) - base) for q in (a, b, p))
    assert min(ra, rb) - 1e-9 <= rp <= max(ra, rb) + 1e-9
    assert min(a[2], b[2]) <= p[2] <= max(a[2], b[2])


def test_a_swing_low_over_the_belt_is_seen_and_one_high_above_it_is_not():
    lay, ik = cell_layout(), Zu12IK()
    x = lay.belt_end_x - 0.3

    def q_at(z, y=lay.belt_y, seed=READY):
        q, why = ik.solve('zu12', [x, y, z], DOWN, 'world', seed)
        assert q is not None, why
        return q

    low = q_at(lay.belt_top + lay.material_size + 0.01)
    high = q_at(lay.belt_top + 0.35)
    assert over_the_belt(lay, low, low, 0.0)
    assert not over_the_belt(lay, high, high, 0.0)
    # What the cup holds hangs below it: a 10 cm material held high enough for the empty cup
    # comes down among what rides on the belt.
    just = q_at(lay.belt_top + lay.material_size + 0.03)
    assert not over_the_belt(lay, just, just, 0.0) and over_the_belt(lay, just, just, 0.1)


def test_a_swing_over_the_end_stop_low_is_seen_and_one_clear_of_it_is_not():
    """The end stop is a wall 6 cm high across the belt's end, higher than the materials it
    holds: lifted 4-5 cm and swung on downstream, what a Panda held scraped over it. A swing
    with what the cup holds over the stop's top, or beside it, clears it."""
    from dataclasses import replace
    lay, ik = cell_layout(), Zu12IK()
    assert lay.end_stop
    lo, hi = end_stop_box(lay)
    assert lo[0] == pytest.approx(lay.belt_end_x) and hi[2] == pytest.approx(
        lay.belt_top + END_STOP_HEIGHT_M)
    assert hi[1] - lo[1] == pytest.approx(lay.belt_width)
    assert tallest_on_belt(lay) == pytest.approx(max(END_STOP_HEIGHT_M, lay.material_size))
    assert end_stop_box(replace(lay, end_stop=False)) is None
    held = 0.05

    def along(z, y=lay.belt_y):
        qs, seed = [], READY
        for x in np.linspace(lay.belt_end_x - 0.1, lay.belt_end_x + 0.06, 9):
            q, why = ik.solve('zu12', [x, y, z], DOWN, 'world', seed)
            assert q is not None, why
            qs.append(q)
            seed = q
        return qs

    top = lay.belt_top + END_STOP_HEIGHT_M
    assert sweeps_into_box(lay, along(top + held + 0.005), (lo, hi), held, 0.02)
    assert not sweeps_into_box(lay, along(top + held + 0.03), (lo, hi), held, 0.02)
    assert sweeps_into_box(lay, along(top + held + 0.03), (lo, hi), held, 0.04)
    # Beside the belt, or straight up along the stop's face: clear, however low.
    beside = lay.belt_y - lay.belt_width / 2 - held / 2 - 0.001
    assert not sweeps_into_box(lay, along(top, beside), (lo, hi), held, 0.02)
    face = lay.belt_end_x - held / 2 - 0.001
    up = []
    for z in np.linspace(lay.belt_top + held, top + held + 0.05, 6):
        q, why = ik.solve('zu12', [face, lay.belt_y, z], DOWN, 'world', READY)
        assert q is not None, why
        up.append(q)
    assert not sweeps_into_box(lay, up, (lo, hi), held, 0.02)


def test_the_lift_line_steps_straight_up_at_most_a_centimetre_apart():
    on = np.array([0.5, 0.7, 0.45])
    points = lift_line(on, on + [0.0, 0.0, 0.07])
    assert len(points) == 6
    assert all(np.allclose(p[:2], on[:2]) for p in points)
    zs = [on[2]] + [p[2] for p in points] + [on[2] + 0.07]
    assert np.allclose(np.diff(zs), 0.01) and max(np.diff(zs)) <= LIFT_LINE_STEP_M + 1e-12
    assert lift_line(on, on + [0.0, 0.0, 0.005]) == []


def test_the_points_over_a_place_clear_what_is_there_and_the_belt():
    t = PickTiming(place_gap=0.002, place_height=0.07, lift_height=0.07)
    target = np.array([0.2, -0.4, 0.0])
    release, above, transfer = place_points(target, 0.05, t, 0.0, belt_top=0.4)
    assert np.allclose(release, target + [0, 0, 0.052])
    assert np.allclose(above, release + [0, 0, 0.07])
    assert np.allclose(transfer[:2], release[:2])
    assert transfer[2] == pytest.approx(0.4 + 0.1 + 0.07)         # over the belt, not the place
    # Materials there already: it swings in over them.
    _, above, _ = place_points(target, 0.05, t, 0.12, belt_top=0.0)
    assert above[2] == pytest.approx(release[2] + 0.12)


def test_two_solutions_a_large_jump_apart_lie_on_two_branches():
    q = np.zeros(6)
    assert continuous([q, q + 0.4, q + 0.8])
    assert not continuous([q, q + np.eye(6)[2] * (IK_JUMP_RAD + 0.01)])
    assert continuous([q])
