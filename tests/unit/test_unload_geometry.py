"""The youBot's unload geometry (cell_layout/unload_geometry.py), each function on its
own: the lift's steps, a grip's points, where a held material is, how far from a drop, and the
check that a motion keeps it clear of the plate's other materials."""
import numpy as np
import pytest

from cell_layout.layout import PLATE_SLOTS_IN_BASE_M, PLATE_TOP_IN_BASE_M
from cell_layout.unload_geometry import (
    PLATE_CLEARANCE_M,
    REGRIP_PRESS_M,
    UNLOAD_LIFT_STEPS_M,
    YOUBOT_GRASP_STANDOFF_M,
    clear_of_the_plate,
    grip_points,
    held_offset,
    lift_steps,
    short_of,
)
from controllers.youbot_kinematics import YoubotKinematics

KIN = YoubotKinematics('gripper_tcp')


def test_the_lift_rises_until_it_clears_the_tallest_neighbour():
    assert lift_steps(0.0) == UNLOAD_LIFT_STEPS_M == lift_steps(0.05)
    steps = lift_steps(0.072)
    assert steps[:len(UNLOAD_LIFT_STEPS_M)] == UNLOAD_LIFT_STEPS_M
    assert steps[-1] >= 0.072 + PLATE_CLEARANCE_M - 1e-9 > steps[-2]
    assert np.allclose(np.diff(steps), 0.01)


def test_a_grip_comes_down_onto_the_top_face_and_presses_further_at_a_second_attempt():
    slot = PLATE_SLOTS_IN_BASE_M[0]
    contact, hover, lift = grip_points(slot, 0.05, 0, high=False, tallest=0.05)
    assert np.allclose(contact, [slot[0], slot[1],
                                 PLATE_TOP_IN_BASE_M + 0.05 + YOUBOT_GRASP_STANDOFF_M])
    assert np.allclose(hover, contact + [0, 0, 0.03])
    assert np.allclose(grip_points(slot, 0.05, 0, high=True, tallest=0.0)[1],
                       contact + [0, 0, 0.05])
    assert [p[2] - contact[2] for p in lift] == pytest.approx(list(UNLOAD_LIFT_STEPS_M))
    assert all(np.allclose(p[:2], contact[:2]) for p in lift)      # straight up
    again, _, _ = grip_points(slot, 0.05, 1, high=False, tallest=0.05)
    assert again[2] == pytest.approx(contact[2] - REGRIP_PRESS_M)


def test_where_the_held_material_is_from_the_tool_and_how_far_a_drop_is():
    q = np.array([0.3, 0.8, -1.2, 1.0, 0.2])
    tool = KIN.fk(q)[:2, 3]
    assert np.allclose(held_offset(q, tool), 0.0)
    assert np.allclose(held_offset(q, tool + [0.004, -0.002]), [0.004, -0.002])
    assert short_of(q, q) == 0.0
    other = q + [0.2, 0, 0, 0, 0]                       # (joint 1 turned: the tool swings)
    assert short_of(q, other) == pytest.approx(
        float(np.linalg.norm(KIN.fk(other)[:2, 3] - tool)))


def _still(q, t0=0.0, t1=1.0):
    zero = np.zeros(5)
    return [(t0, q, zero, zero), (t1, q, zero, zero)]


def test_a_motion_is_clear_of_the_plate_only_where_what_it_holds_passes_over_the_others():
    q = np.array([0.2, 0.6, -1.0, 0.4, 0.0])
    tool = KIN.fk(q)[:3, 3]
    size = 0.05
    bottom = tool[2] - YOUBOT_GRASP_STANDOFF_M - size           # what it holds, its bottom
    # A neighbour right under it whose top is within PLATE_CLEARANCE_M of that bottom: not
    # clear; a lower one: clear; one beside it, or none: clear.
    tall = bottom - PLATE_TOP_IN_BASE_M - PLATE_CLEARANCE_M + 0.002
    short = bottom - PLATE_TOP_IN_BASE_M - PLATE_CLEARANCE_M - 0.002
    assert not clear_of_the_plate(_still(q), [(tool[0], tool[1], tall)], size)
    assert clear_of_the_plate(_still(q), [(tool[0], tool[1], short)], size)
    assert clear_of_the_plate(_still(q), [(tool[0] + 0.3, tool[1], tall)], size)
    assert clear_of_the_plate(_still(q), [], size)
    # Held off the tool's centre (held_offset), it is judged where it is.
    assert not clear_of_the_plate(_still(q), [(tool[0] + 0.06, tool[1], tall)], size,
                                  offset=(0.06, 0.0))
    # Between samples, along the path the controller follows: a swing through the neighbour.
    away = q + [0.6, 0, 0, 0, 0]
    zero = np.zeros(5)
    swing = [(0.0, q - [0.6, 0, 0, 0, 0], zero, zero), (1.0, away, zero, zero)]
    assert not clear_of_the_plate(swing, [(tool[0], tool[1], tall)], size)
