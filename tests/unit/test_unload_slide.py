"""A heavy material is let go where the youBot's arm holds it: the base slides along its stand's
line, clear of the world's obstacles, to stand abeam a drop its arm cannot hold the material
out to from the stand itself (0.44-0.47 kg blues held out over the platform's far slot
stalled the arm and were left on the plate)."""
import copy
import math

import numpy as np
import pytest
from test_cell_rules import world
from test_material_classes import PAPER_CLASSES as PAPER
from test_pipeline import _YoubotIK, observation

from cell_layout.layout import YOUBOT_CARRY_Q
from cell_layout.reach import youbot_holds
from cell_layout.world_layout import (
    STAND_SLIDE_MAX_M,
    YOUBOT_HALF_LENGTH_M,
    layout_from_world,
    stand_slide,
)
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M
from coordinator.pipeline import Material, Pipeline, Settings
from coordinator.pipeline.model import TransportState
from coordinator.pipeline.unload_planner import SLIDE_MIN_M


def test_the_paper_s_stands_slide_the_whole_way_along_the_pool_s_wall():
    """Beside the pool's west wall (the wheels 3.1 cm off it) the base is clear where it stands
    and all along the wall: nothing stands ahead or behind within STAND_SLIDE_MAX_M."""
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    for stand in layout.stands:
        assert stand.slide == (-STAND_SLIDE_MAX_M, STAND_SLIDE_MAX_M), stand.name


def test_an_obstacle_ahead_of_a_stand_ends_its_slide_and_a_mark_on_the_floor_does_not():
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    left = layout.stand('pool_left')            # facing south (-y) at (1.54, -1.6)
    x, y, _ = left.pose
    crate = {'shape': 'box', 'size': [0.2, 0.2, 0.3], 'position': [x, y - 0.6, 0.15]}
    mark = dict(crate, position=[x, y + 0.6, 0.001], size=[0.2, 0.2, 0.002])
    w = world(copy.deepcopy(PAPER), obstacles=[crate, mark])
    slide = stand_slide(left.pose, w.obstacles, w.floor_size)
    # Its front (half its length and the clearance ahead) meets the crate's north face
    # (0.5 m ahead of the stand): 0.5 - 0.29 - 0.05 = 0.16 m.
    assert slide[1] == pytest.approx(0.5 - YOUBOT_HALF_LENGTH_M - 0.05, abs=0.011)
    assert slide[0] == -STAND_SLIDE_MAX_M                      # (the mark is driven over)
    # Standing inside an obstacle: no slide at all.
    inside = dict(crate, position=[x, y, 0.15])
    w = world(copy.deepcopy(PAPER), obstacles=[inside])
    assert stand_slide(left.pose, w.obstacles, w.floor_size) == (0.0, 0.0)


def test_abeam_brings_the_arm_s_base_level_with_a_point_within_the_slide():
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    right = layout.stand('pool_right')          # facing north (+y) at (1.54, -1.25)
    x, y, yaw = right.pose
    at = right.abeam((2.0, -1.45))
    arm = (at[0] + ARM_BASE_IN_BASE_LINK_M[0] * math.cos(yaw),
           at[1] + ARM_BASE_IN_BASE_LINK_M[0] * math.sin(yaw))
    assert at[0] == pytest.approx(x) and at[2] == yaw       # along its line, same heading
    assert arm[1] == pytest.approx(-1.45)
    far = right.abeam((2.0, -9.0))                          # beyond its slide: its end
    assert far[1] == pytest.approx(y + right.slide[0])


@pytest.mark.slow
@pytest.mark.parametrize('mass', [0.45, 0.5])
def test_a_heavy_material_is_held_all_the_way_to_every_pool_drop(mass):
    """From each slot of a stand's row, every drop of the stand is reached by a way whose every
    pose from the grip on holds the material at rest (youbot_holds): from the stand, or from
    the base slid abeam the drop. Some drops need the slide (without it, their way stalls the
    arm), and a slid base stays on its stand's line, within its slide."""
    classes = copy.deepcopy(PAPER)
    classes['orange'].update(count=13, mass=mass)
    layout = layout_from_world(world(classes))
    run_ = Pipeline(layout, _YoubotIK(), Settings())
    tr = run_.transport
    slid = 0
    for stand in layout.stands:
        row = [k for k in range(len(layout.plate_slots)) if layout.slot_row(k) == stand.row]
        for k in row[::2]:
            m = Material(1, 'orange', np.zeros(3), 0.0, 3, status='on_plate', slot=k, size=0.05)
            run_.materials.clear()
            run_.materials[1] = m
            for d in range(len(stand.drops)):
                run_.book._dropped = {stand.name: set(range(len(stand.drops))) - {d}}
                path = tr.planner.unload_path(m, stand.pose, YOUBOT_CARRY_Q, high=True, slide=True)
                assert path is not None and path.place == d, (stand.name, k, d)
                assert youbot_holds([path.contact, *path.lift, path.over, path.drop], mass)
                if path.pose is not stand.pose:
                    slid += 1
                    assert path.pose[2] == stand.pose[2]
                    along = np.subtract(path.pose[:2], stand.pose[:2])
                    heading = np.array([math.cos(stand.pose[2]), math.sin(stand.pose[2])])
                    assert abs(heading[0] * along[1] - heading[1] * along[0]) < 1e-9  # its line
                    assert stand.slide[0] - 1e-9 <= along @ heading <= stand.slide[1] + 1e-9
                    assert np.linalg.norm(along) >= SLIDE_MIN_M
                    # Without the slide, the arm holds it out to no drop as the base stands.
                    assert all(tr.planner.unload_way(m, stand.pose, YOUBOT_CARRY_Q, True, mass, [
                        (d, stand.drops[d])], 0.0, level) is None for level in (True, False))
    assert slid > 0


@pytest.mark.slow
def test_an_unload_from_elsewhere_on_the_stand_s_line_drives_there_as_the_arm_goes_down():
    """Standing at its stand, the youBot slides to the drop's pose (the drive's goal is still
    the stand: its drops are the stand's) while the arm goes down onto the material; the plan
    for the material as the base stands there is made for that pose."""
    class Ports(_YoubotIK):
        followed = None

        def follow(self, robot, follower):
            Ports.followed = follower
            return True

        def drive(self, robot, *twist):
            pass

        def trajectory(self, arm, points, start, continuing=False):
            return 0.0

    classes = copy.deepcopy(PAPER)
    classes['orange'].update(count=13, mass=0.5)
    layout = layout_from_world(world(classes))
    run_ = Pipeline(layout, Ports(), Settings())
    tr = run_.transport
    stand = layout.stand('pool_right')
    m = Material(1, 'orange', np.zeros(3), 0.0, 3, status='on_plate', slot=1, size=0.05)
    run_.materials[1] = m
    tr.queue, tr.base.goal = [m], stand.name
    tr.state = TransportState.DRIVE                       # (there, the base standing)
    # Only a far drop left: held out to only from further along the wall.
    far = max(range(len(stand.drops)), key=lambda d: np.linalg.norm(
        np.asarray(stand.abeam(stand.drops[d])[:2]) - stand.pose[:2]))
    run_.book._dropped = {stand.name: set(range(len(stand.drops))) - {far}}
    tr._plan_unload(observation(0.0, np.zeros(6), YOUBOT_CARRY_Q, stand.pose), m)
    assert tr.state is TransportState.GRASP and tr.base.driving
    assert tr.base.goal == stand.name and tr._carry.place == far
    assert tr.base.target == tr._carry.pose == stand.abeam(stand.drops[far])
    end = Ports.followed.path.key_poses[-1]
    assert tuple(end) == pytest.approx(tr.base.target)
    assert tr.base.stand_pose(None) == tr.base.target       # (what it plans for while it drives)
