"""The Zu 12 meets a material that comes to rest in the end stop's queue once it rests there,
not on the move into it; a swing from a low lift clears what rides on the belt (real Zu 12
IK)."""
import math
from dataclasses import replace

import numpy as np
import pytest
from test_zu12_swing import READY, _cell

from cell_layout import lift_swing
from cell_layout.lift_swing import rise_first
from cell_layout.pick_geometry import tallest_on_belt
from cell_layout.reach import tool_points
from controllers.pick_place import PickTiming
from coordinator.pipeline import Material, pick_planner
from coordinator.pipeline.clock import Clock
from coordinator.pipeline.materials import BeltModel
from coordinator.pipeline.model import DOWN, QUEUE_LIFT_PAUSE_LEAD_S


def test_a_material_about_to_come_to_rest_in_the_queue_is_met_at_rest_there():
    """A blue met on the move 3 cm short of where it comes to rest behind the purple the stop
    held: the cup carried it on into the purple (the camera's estimate 4 mm behind) and the
    lift dragged the purple off the belt's end. Its contact waits until it rests there, then
    the belt's pause (QUEUE_LIFT_PAUSE_LEAD_S before the contact) and the straight lift apply;
    a material that rests against nothing (the stop's face) is met on the move as before."""

    layout, run_, zu12 = _cell(0.05, 1)
    end, speed = layout.belt_end_x, layout.belt_speed
    purple = Material(1, 'purple', np.array([end - 0.021, layout.belt_y, 0.42]), 0.0, 3,
                      size=0.042)
    blue = Material(2, 'blue', np.array([end - 0.12, layout.belt_y, 0.425]), 0.0, 3, size=0.05)
    run_.materials.update({1: purple, 2: blue})
    belt = BeltModel(layout, run_.materials, Clock(0.0), ran_before=True)
    run_.belt = zu12.belt = zu12.planner.belt = belt
    run_.belt.running = True
    belt, timing = run_.belt, PickTiming()
    assert belt.held(purple) and not belt.held(blue)
    rest = belt.comes_to_rest(blue)
    gap = (end - 0.042) - 0.003 - 0.025 - (end - 0.12)     # to 3 mm behind the purple
    assert rest == pytest.approx(gap / speed, abs=1e-3)
    assert not belt.held_by(blue, rest - 0.01) and belt.held_by(blue, rest)
    # Met just before it rests: later, at rest.
    contact = rest - 0.2
    met = zu12.planner.not_as_it_queues(blue, contact, timing)
    assert met == pytest.approx(rest + QUEUE_LIFT_PAUSE_LEAD_S + pick_planner.QUEUE_REST_S)
    assert belt.held_by(blue, met - QUEUE_LIFT_PAUSE_LEAD_S)         # at rest as the belt pauses
    # Met just after it rests, before the belt's pause would begin: later too (the belt
    # paused 0.35 s before it came to rest, it stopped 8 cm short, and the cup missed it).
    assert zu12.planner.not_as_it_queues(blue, rest + 0.3, timing) == pytest.approx(met)
    # At rest long enough before the pause: unchanged.
    settled = rest + QUEUE_LIFT_PAUSE_LEAD_S + pick_planner.QUEUE_REST_S + 0.05
    assert zu12.planner.not_as_it_queues(blue, settled, timing) == settled
    # Met well before it gets there (it rests after the lift): unchanged.
    early = rest - timing.dwell - timing.lift - 0.1
    assert zu12.planner.not_as_it_queues(blue, early, timing) == early
    # Nothing held ahead of it: it comes to rest against the stop alone, met on the move.
    run_.materials.pop(1)
    assert zu12.planner.not_as_it_queues(blue, belt.comes_to_rest(blue) - 0.2, timing) == (
        belt.comes_to_rest(blue) - 0.2)


def _two_at_the_stop():
    """A cell whose end stop holds a 50 mm material and another right behind it (belt on)."""
    layout, run_, zu12 = _cell(0.05, 1)
    end = layout.belt_end_x
    ahead = Material(1, 'purple', np.array([end - 0.025, layout.belt_y, 0.425]), 0.0, 3,
                     size=0.05)
    behind = Material(2, 'orange', np.array([end - 0.078, layout.belt_y, 0.425]), 0.0, 3,
                      size=0.05)
    run_.materials.update({1: ahead, 2: behind})
    belt = BeltModel(layout, run_.materials, Clock(0.0), ran_before=True)
    run_.belt = zu12.belt = zu12.planner.belt = belt
    run_.belt.running = True
    return layout, run_, zu12, ahead, behind


def test_a_lift_out_of_the_queue_rises_over_the_tallest_material_that_can_stand_next_to_it():
    """Lifted from behind an orange, a green rose 7 cm and its swing on sagged 1.3 cm and bulged
    2 cm sideways onto the orange, and knocked it over. Out of the queue the lift rises until
    what the cup holds passes QUEUE_SWING_CLEARANCE_M over the tallest material of the batch;
    a pick on the move keeps its lift."""
    from types import SimpleNamespace
    layout, run_, zu12, _, green = _two_at_the_stop()
    timing = run_.s.timing                 # (the cell's: a 7 cm lift)
    queued = SimpleNamespace(m=green, timing=timing, contact=1.0)
    high = zu12.planner.lifting(queued).lift_height
    assert high == pytest.approx(layout.material_size + pick_planner.QUEUE_SWING_CLEARANCE_M)
    assert high > timing.lift_height
    run_.materials.pop(1)                  # alone at the stop: the lift as before
    assert zu12.planner.lifting(queued).lift_height == timing.lift_height


def test_the_belt_pauses_for_a_lift_only_with_a_material_behind():
    """The belt presses the queue from behind: a lift with a material right behind pauses it;
    one with only the stop's material ahead (the paper's orange behind its purple) does not
    (the paper's belt had paused 5 times in 110 trials)."""
    _, run_, _, purple, orange = _two_at_the_stop()
    belt = run_.belt
    assert belt.crowded(orange, 0.0) and not belt.crowded(orange, 0.0, behind=True)
    assert belt.crowded(purple, 0.0) and belt.crowded(purple, 0.0, behind=True)


def _swing(zu12, layout, start, end, steps=12):
    """The joints as the cup goes in a straight line from ``start`` to ``end`` (world), one
    sample a tenth of a second."""
    q, points = READY, []
    for k in range(steps + 1):
        q = zu12.arm.solve(start + (end - start) * k / steps, DOWN, 'world', q)
        assert q is not None
        points.append((0.1 * k, q, np.zeros(6), np.zeros(6)))
    return points


def test_a_swing_from_a_low_lift_into_a_material_on_the_belt_rises_straight_up_first():
    """Lifted 4 cm off the belt 11 cm behind a purple riding ahead of it, a Panda's swing to
    the plate went downstream, 1-2 cm over the purple's top as planned, lower as the arm
    followed it: what its cup held dragged the purple 12 cm along and off the belt, and the
    shock drove its wrist past its speed limit. A way from the lift point that comes within
    the cell's swing clearance (2 cm here) of a material on the belt (where the belt has it at
    the way's start or a second on) rises straight up first, until what the cup holds passes
    RISE_OVER_M over the tallest thing on the belt or at its end, and higher while the way on
    from there is not clear; one that keeps clear goes as planned."""
    layout, run_, zu12, purple, orange = _two_at_the_stop()
    run_.materials.pop(2)
    layout = replace(layout, swing_clearance=0.02)
    purple.position = np.array([layout.belt_end_x - 0.2, layout.belt_y, 0.425])
    held = Material(3, 'orange', np.zeros(3), 0.0, 3, size=0.05)
    belt, top = run_.belt, layout.belt_top
    belt.running = False                               # (the purple where it is)
    # (What the cup holds 1.5 cm over the purple's top: clear of it, as planned.)
    lift = np.array([purple.position[0] - 0.11, layout.belt_y, top + 0.05 + 0.05 + 0.015])
    asked = []

    def riding(t):
        return [(f'{o.color} {o.id}', [(np.array([*belt.track(o)(t)[:2], top]), o.size)])
                for o in belt.on_belt()]

    def solve(point, seed):
        return zu12.arm.solve(point, DOWN, 'world', seed)

    def planned(along):
        """A way from where the cup is (after the rise, if any) along ``along``."""
        def way(up):
            asked.append(up)
            start = tool_points(layout, [up[-1]])[0] if up else lift
            rise = _swing(zu12, layout, lift, start, 3) if up else []
            return rise + [(p[0] + 1.0, *p[1:]) for p in _swing(zu12, layout, start,
                                                                  start + along)]
        return way

    def rises(along):
        asked.clear()
        return rise_first(layout, lift, held.size, READY, planned(along), riding, solve,
                          -math.inf)

    downstream = np.array([0.2, -0.02, 0.0])
    motion, why = rises(downstream)
    assert why == ['up 0.045 m first: its swing came near purple 1']   # (over the stop's 6 cm)
    assert len(asked) == 2 and len(asked[1]) == 1       # up once, and clear from there
    cup = tool_points(layout, [asked[1][0]])[0]
    assert cup[:2] == pytest.approx(lift[:2], abs=1e-6)
    assert cup[2] - held.size == pytest.approx(
        top + tallest_on_belt(layout) + lift_swing.RISE_OVER_M)
    assert np.allclose(motion[-1][1], _swing(zu12, layout, cup, cup + downstream)[-1][1])
    # A way on that dips back down near the purple from there: higher again, then given up
    # (the last one planned goes).
    _, why = rises(downstream + [0.0, 0.0, -0.3])
    assert len(asked) == 1 + lift_swing.RISE_LEVELS == 1 + len(why)
    heights = [tool_points(layout, [up[0]])[0][2] for up in asked[1:]]
    assert np.allclose(np.diff(heights), lift_swing.RISE_OVER_M)
    # Sideways, away from the purple, or nothing on the belt: as planned.
    assert rises(np.array([-0.05, -0.25, 0.0]))[1] == [] and asked == [[]]
    run_.materials.pop(1)
    assert rises(downstream)[1] == [] and asked == [[]]
