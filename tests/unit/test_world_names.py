"""A world names only what ROS accepts, no two things of its graph share a name, and every robot
stands where it can (issue 62): each failure found by the fourth round of probes, refused in one
line when the world is read, before any node starts."""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Callable, Dict

import pytest
import yaml

from cell_layout.layout import LayoutError
from cell_layout.world_layout import layout_from_world
from studies.campaign import CampaignError
from studies.plan import check_world
from world_description.graph_names import graph_names
from world_description.resources import resolve_resource
from world_description.ros_names import MAX_NAME_LENGTH, name_problem
from world_description.world_config import WorldConfigError, load_world, parse_world

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')
TWO = resolve_resource('package://world_description/worlds/cell_two_youbots.yaml')
WORLDS = sorted(resolve_resource('package://world_description/worlds/x.yaml').parent
                .glob('*.yaml'))


def _data(path: Path = CELL) -> Dict[str, Any]:
    from world_description.world_loading import world_data
    return copy.deepcopy(world_data(path))


def _robot(data: Dict[str, Any], name: str) -> Dict[str, Any]:
    return next(r for r in data['robots'] if r['name'] == name)


def _refused(data: Dict[str, Any], *words: str) -> str:
    with pytest.raises(WorldConfigError) as err:
        parse_world(data, 'my.yaml')
    text = str(err.value)
    assert text.startswith('my.yaml: ') and '\n' not in text, text
    assert all(w in text for w in words), text
    return text


def _renamed(name: str) -> Callable[[Dict[str, Any]], None]:
    def change(data: Dict[str, Any]) -> None:
        robot = _robot(data, 'youbot')
        robot['name'] = name
        del robot['namespace']           # (its namespace is its name)
        data['cell'] = {'loader': 'zu12', 'transports': [name]}
    return change


@pytest.mark.parametrize('name, words', [
    ('y' * 250, ('robots[1].name', 'is 250 characters long (at most 64)')),
    ('y' * 5000, ('robots[1].name', 'is 5000 characters long (at most 64)')),
    ('youbot2\n', ('robots[1].name', 'must be a ROS name')),
    ('youbot 2', ('robots[1].name', 'must be a ROS name')),
    ('2youbot', ('robots[1].name', 'must be a ROS name')),
])
def test_a_robots_name_is_a_ros_name_of_a_bounded_length(name, words):
    """A name of 250 or 5,000 characters was taken, and the trial crashed (ENAMETOOLONG on its
    log file); "youbot2\\n" was taken (the schema's $ takes a trailing newline), and the nodes
    crashed."""
    data = _data()
    _renamed(name)(data)
    _refused(data, *words)


@pytest.mark.parametrize('field, value, words', [
    ('namespace', 'cell//youbot', ('namespace', 'has an empty part')),
    ('namespace', 'cell/2youbot', ('namespace', 'has the part')),
    ('namespace', 'youbot\n', ('namespace', 'has the part')),
    ('namespace', '/'.join(['n' * 60] * 5), ('namespace', 'characters long (at most 245)')),
    ('frame_prefix', 'you bot/', ('frame_prefix', "must be a frame name's start")),
    ('frame_prefix', 'y' * 70 + '/', ('frame_prefix', 'at most 64 characters')),
    ('frame_prefix', 'zu12/', ('frame prefixes must be unique',)),
])
def test_namespaces_and_frame_prefixes_follow_the_rules(field, value, words):
    data = _data()
    _robot(data, 'youbot')[field] = value
    _refused(data, *words)


def test_names_the_graph_makes_from_long_parts_are_refused_by_ros_length():
    """Each part within its limit, the names they make together past ROS's 247 characters."""
    data = _data()
    robot = _robot(data, 'youbot')
    robot['namespace'] = '/'.join(['n' * 60] * 3)                   # 182 characters
    robot['controllers'][0]['name'] = 'c' * 60
    _refused(data, 'makes the', f'(ROS takes at most {MAX_NAME_LENGTH})')


def test_a_grip_service_on_the_simulators_own_reset_is_refused():
    """A youBot whose namespace and grip service landed on sim_node's own reset was taken: the
    simulator crashed."""
    data = _data()
    robot = _robot(data, 'youbot')
    robot['namespace'] = 'sim_node'
    robot['suction']['service'] = 'reset'
    _refused(data, "robot youbot's grip service makes the service /sim_node/reset",
             'the simulator (sim_node) makes too')


def test_two_youbots_grip_services_on_one_name_are_refused():
    """Two grip services that come out as one name were taken: the run delivered 7 of 16."""
    data = _data(TWO)
    first, second = _robot(data, 'youbot'), _robot(data, 'youbot2')
    first['namespace'], first['suction']['service'] = 'fleet', 'two/grasp'
    second['namespace'], second['suction']['service'] = 'fleet/two', 'grasp'
    _refused(data, 'makes the service /fleet/two/grasp, which', 'makes too')


def test_two_cameras_of_one_name_are_refused():
    data = _data()
    data['cameras'].append(dict(data['cameras'][0], position=[0.0, 0.75, 1.25]))
    _refused(data, 'cameras[1] (belt_camera) makes the topic /belt_camera/image_raw, which '
             'cameras[0] (belt_camera) makes too')


@pytest.mark.parametrize('path', WORLDS, ids=lambda p: p.name)
def test_every_shipped_world_makes_valid_names_once(path):
    names = graph_names(load_world(path))
    assert all(name_problem(n.name) == '' for n in names)
    owners: Dict[tuple, str] = {}
    for n in names:
        assert owners.setdefault((n.kind, n.name), n.owner) == n.owner, n


# -- every robot stands where it can ----------------------------------------------------------

def _check(data: Dict[str, Any], tmp_path: Path) -> None:
    path = tmp_path / 'cell.yaml'
    path.write_text(yaml.safe_dump(data))
    check_world(str(path))


@pytest.mark.parametrize('robot, where, words', [
    ('youbot', (-0.3, 0.75), 'robot youbot: its start pose overlaps obstacle conveyor'),
    ('youbot', (2.1, -1.3), 'robot youbot: its way from .* runs over obstacle pool_wall'),
    ('zu12', (-0.3, 0.75), 'robot zu12: its base stands inside obstacle conveyor'),
])
def test_a_robot_inside_the_conveyor_or_the_pool_is_refused(tmp_path, robot, where, words):
    """The fleet check returned early for one youBot: a youBot inside the conveyor was taken,
    and the run wrote a record the runner's own reader refused."""
    data = _data()
    _robot(data, robot)['pose'].update(x=where[0], y=where[1])
    with pytest.raises(CampaignError, match=words):
        _check(data, tmp_path)


def test_a_loader_on_a_pedestal_stands_on_it_and_one_inside_it_is_refused():
    data = _data()
    data['obstacles'].append({'name': 'pedestal', 'shape': 'box', 'size': [0.3, 0.3, 0.1],
                              'position': [0.0, 0.0, -0.05]})
    layout_from_world(parse_world(data))
    data['obstacles'][-1]['position'] = [0.0, 0.0, 0.05]
    with pytest.raises(LayoutError, match='robot zu12: its base stands inside obstacle '
                                          'pedestal'):
        layout_from_world(parse_world(data))


def test_identifications_are_counted_by_material():
    """The same material identified again and again (a youBot inside the belt held it in the
    camera's view) made an identification rate of 138 %."""
    from trial_record.scoring import identified_materials
    details = [{'truth_id': 0}, {'truth_id': 0}, {'truth_id': 0}, {'truth_id': 1},
               {'truth_id': 2}, {'truth_id': 2}, {'truth_id': None}]
    assert identified_materials([True, True, True, True, True, False, False], details) == 2
    assert identified_materials([True] * 7, details) == 3
    assert identified_materials([True, False], None) == 1
