"""A recorded trial's storyboard (studies/storyboard.py): its phases from the events, the
states recorded last before each, a robot posed where it truly was (its perturbations undone),
and a camera that sees the whole of any cell."""
import math

import numpy as np
import pybullet
import pytest

from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from studies.storyboard import (
    PANEL,
    Event,
    Material,
    Recording,
    _inside,
    overview_camera,
    phases,
    storyboard,
)
from world_description.footprint import footprints
from world_description.resources import resolve_resource
from world_description.world_config import load_world

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')
WORLDS = ('pipeline_cell', 'cell_four_classes', 'mini_robot', 'youbot')


def _events(*kinds):
    return [Event(10.0 + i, kind, color, f'detail {i}') for i, (kind, color) in
            enumerate(kinds)]


def test_each_phase_is_the_first_event_of_its_kind_in_time_order():
    events = _events(('belt_started', ''), ('seen', 'orange'), ('picked', 'orange'),
                     ('loaded', 'orange'), ('picked', 'purple'), ('departing', ''),
                     ('placed', 'purple'), ('loading_over', ''), ('delivered', 'orange'),
                     ('delivered', 'orange'), ('finished', ''))
    found = phases(list(reversed(events)))            # (in any order)
    assert [p.caption for p in found] == [
        'start', 'first grasp', 'first load', 'youBot departs', 'purple placed',
        'loading over', 'first unloaded', 'both home']
    assert [p.time for p in found] == [10.0, 12.0, 13.0, 15.0, 16.0, 17.0, 18.0, 20.0]
    assert [p.since_start for p in found][:2] == [0.0, 2.0]
    assert found[1].detail == 'detail 2' and found[0].detail == ''


def test_the_first_trouble_is_a_phase_of_its_own():
    found = phases(_events(('belt_started', ''), ('picked', 'orange'), ('grasp_missed', 'blue'),
                           ('arm_stalled', ''), ('finished', '')))
    assert [p.caption for p in found] == ['start', 'first grasp',
                                          'first trouble: grasp missed (blue)', 'both home']
    assert found[2].time == 12.0 and found[2].detail == 'detail 2'


def test_phases_that_never_happened_are_left_out():
    # A cell without a transport, stopped before its end.
    found = phases(_events(('belt_started', ''), ('picked', 'red'), ('placed', 'red')))
    assert [p.caption for p in found] == ['start', 'first grasp', 'red placed']
    assert phases([]) == []


def test_a_moment_shows_the_state_recorded_last_before_it():
    series = [(1.0, 'a'), (2.0, 'b'), (3.0, 'c')]
    assert Recording.at(series, 2.5) == 'b'
    assert Recording.at(series, 2.0) == 'b'
    assert Recording.at(series, 2.0 - 1e-4) == 'b'      # (the same tick, rounded)
    assert Recording.at(series, 0.5) == 'a'
    assert Recording.at(series, 9.0) == 'c'
    assert Recording.at([], 1.0) is None


@pytest.mark.parametrize('name', WORLDS)
def test_the_overview_camera_sees_the_whole_cell(name):
    world = load_world(resolve_resource(f'package://world_description/worlds/{name}.yaml'))
    view, projection = overview_camera(world, PANEL)
    for f in footprints(world):
        points = np.column_stack((f.outline, np.zeros(len(f.outline))))
        assert _inside(points, view, projection, 1.0), f.name
        assert _inside(points + (0.0, 0.0, 0.5), view, projection, 1.0), f.name
    # ... and not from so far that the cell is a speck.
    assert not _inside(np.array([[-20.0, 0.0, 0.0], [20.0, 0.0, 0.0]]), view, projection, 1.0)


def _cell(tmp_path):
    path = tmp_path / 'drifting.yaml'
    path.write_text(f'extends: {CELL}\nperturbations:\n'
                    '  robots: {joint_offset: 0.03, odometry_drift: 0.1}\n')
    return load_world(path)


def test_a_robot_is_shown_where_it_was_not_where_its_encoders_and_odometry_said(tmp_path):
    config = _cell(tmp_path)
    ran, shown = SimWorld(config, scenario_seed=3), SimWorld(config, scenario_seed=3)
    try:
        youbot = ran.robots['youbot']
        assert youbot.sensors.odometry_scale != (1.0, 1.0, 1.0)
        runner = SimRunner(ran, DriveLimits(), 100.0)
        for _ in range(12):
            runner.command('youbot', 0.2, -0.1, 0.4)
            runner.advance(round(0.1 / ran.time_step), NullSink())
        rng = np.random.default_rng(1)
        zu12 = ran.robots['zu12']
        arm = [zu12.joint_index[f'joint_{i}'] for i in range(1, 7)]
        for j in arm:
            ran.client.resetJointState(zu12.body, j, float(rng.uniform(-1.0, 1.0)))
        for name, robot in ran.robots.items():
            states, odom = robot.sensors.joint_states(), robot.sensors.base_state()
            twin = shown.robots[name]
            twin.sensors.pose_as_reported(states.names, states.positions)
            if robot.drive is not None:
                twin.sensors.place_as_reported(odom.position, odom.orientation)
            truth = [s[0] for s in ran.client.getJointStates(robot.body, robot.movable)]
            posed = [s[0] for s in shown.client.getJointStates(twin.body, twin.movable)]
            assert posed == pytest.approx(truth, abs=1e-9), name
            (p, q), (p2, q2) = robot.base_link_world(), twin.base_link_world()
            assert p2 == pytest.approx(p, abs=1e-6), name
            # (PyBullet's poses are single precision.)
            assert pybullet.getEulerFromQuaternion(q2) == pytest.approx(
                pybullet.getEulerFromQuaternion(q), abs=1e-6), name
        # The drift was real: the odometry alone puts the base elsewhere.
        odom = youbot.sensors.base_state().position
        start = youbot.start_pose[0]
        assert math.dist((odom[0] + start[0], odom[1] + start[1]),
                         youbot.base_link_world()[0][:2]) > 0.005
    finally:
        ran.close()
        shown.close()


def _pixel(world, point):
    view, projection = overview_camera(world, PANEL)
    v = np.asarray(view).reshape(4, 4).T
    p = np.asarray(projection).reshape(4, 4).T
    h = p @ v @ np.append(point, 1.0)
    x, y = h[:2] / h[3]
    return int((y * -0.5 + 0.5) * PANEL[1]), int((x * 0.5 + 0.5) * PANEL[0])


def test_a_storyboard_draws_one_captioned_picture_per_phase():
    world = load_world(CELL)
    spot = (0.0, -1.5, 0.05)                       # (an empty stretch of floor)
    cube = Material(('orange', 1), spot, (0.0, 0.0, 0.0, 1.0), (0.1,) * 3,
                    (1.0, 0.5, 0.0, 1.0))
    recording = Recording(
        events=_events(('belt_started', ''), ('picked', 'orange'), ('finished', '')),
        joints={'zu12': [(10.0, (['joint_1', 'joint_2'], [0.0, 0.0])),
                         (11.0, (['joint_1', 'joint_2'], [1.2, 0.6]))]},
        odometry={'youbot': [(10.0, ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))),
                             (12.0, ((0.9, -1.0, 0.0), (0.0, 0.0, 0.7071068, 0.7071068)))]},
        materials=[(10.0, []), (12.0, [cube])])
    img = storyboard(recording, world, 0, 1 / 240, 'a test')
    h, w = PANEL[1] + 46, PANEL[0]
    assert img.shape == (40 + h + 6, 3 * (w + 6), 3)
    panels = [img[40 + 46:40 + h, k * (w + 6):k * (w + 6) + w].astype(int) for k in range(3)]
    # The arm moved between the first two pictures, the base between the last two ...
    assert (np.abs(panels[0] - panels[1]).sum(axis=2) > 30).mean() > 0.002
    assert (np.abs(panels[1] - panels[2]).sum(axis=2) > 30).mean() > 0.002
    # ... and the material appeared where the recording put it (BGR).
    row, col = _pixel(world, spot)
    b, g, r = panels[2][row, col]
    assert r > 150 and b < 90 and r - g > 60, (r, g, b)
    assert not np.array_equal(panels[1][row, col], panels[2][row, col])


def test_a_state_that_is_not_finite_leaves_the_robot_where_it_was():
    world = SimWorld(load_world(CELL))
    try:
        youbot = world.robots['youbot']
        before = youbot.base_link_world()[0]
        youbot.sensors.place_as_reported((math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        assert youbot.base_link_world()[0] == before
        zu12 = world.robots['zu12']
        joints = [zu12.joint_index['joint_1']]
        was = zu12.client.getJointState(zu12.body, joints[0])[0]
        zu12.sensors.pose_as_reported(['joint_1', 'no_such_joint'], [math.inf, 1.0])
        assert zu12.client.getJointState(zu12.body, joints[0])[0] == was
    finally:
        world.close()
