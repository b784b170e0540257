"""The world names the cell's robots and their roles (its ``cell`` section): the controller
talks to them by their names and namespaces, not by the paper's; a world without the section
is the paper's cell; roles the controller cannot drive are refused at start-up in one line."""
import copy
import dataclasses

import pytest
import yaml
from test_pipeline import PAPER, FakeCell, run

from cell_layout.layout import LayoutError
from cell_layout.world_layout import layout_from_world
from studies.trial_graph import pipeline_graph
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world, parse_world

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')


def _paper():
    with open(CELL, encoding='utf-8') as f:
        return yaml.safe_load(f)


def renamed(loader='arm', transport='carrier', cell=True):
    """The paper's cell with its robots under other names, namespaces and frame prefixes."""
    data = _paper()
    for robot, name in zip(data['robots'], (loader, transport)):
        robot['name'], robot['namespace'] = name, f'cell_{name}'
        robot['frame_prefix'] = f'cell_{name}/'
    if cell:
        data['cell'] = {'loader': loader, 'transports': [transport]}
    return data


def test_a_world_without_a_cell_section_is_the_papers_cell():
    layout = layout_from_world(load_world(CELL))
    assert (layout.loader.name, layout.transport.name) == ('zu12', 'youbot')
    assert layout.loader.topic('joint_states') == '/zu12/joint_states'
    assert layout.loader.grip == '/zu12/suction'
    assert layout.transport.grip == '/youbot/gripper/grasp'
    assert layout.transport.topic('cmd_vel') == '/youbot/cmd_vel'


def test_the_controller_talks_to_the_robots_the_world_names():
    layout = layout_from_world(parse_world(renamed()))
    assert list(layout.robots) == ['arm', 'carrier']
    assert layout.loader.topic('solve_ik') == '/cell_arm/solve_ik'
    assert layout.loader.grip == '/cell_arm/suction'
    assert layout.transport.topic('odom') == '/cell_carrier/odom'
    assert layout.transport.grip == '/cell_carrier/gripper/grasp'
    # The whole run, against the fake cell, under the world's names.
    # (The fake knows the youBots by the layout's names, and its arm as zu12.)
    cell = Renamed(FakeCell(layout, PAPER), {'arm': 'zu12', 'carrier': 'carrier'})
    p = run(cell)
    assert p.result.status == 'completed' and p.result.delivered == 8
    robots = {e.robot for e in cell.events}
    assert {'arm', 'carrier'} <= robots and not robots & {'zu12', 'youbot'}
    assert p.result.loader_grasp_successes == 8 and p.result.transport_grasp_successes == 7


class Renamed:
    """The fake cell (which knows its arm as zu12), seen by the pipeline under other names:
    each port call's arm and each observation's keys translated."""

    def __init__(self, cell, names):
        object.__setattr__(self, '_cell', cell)
        object.__setattr__(self, '_to', names)
        object.__setattr__(self, '_back', {v: k for k, v in names.items()})

    def __getattr__(self, name):
        return getattr(self._cell, name)

    def __setattr__(self, name, value):
        setattr(self._cell, name, value)

    def solve(self, arm, *args):
        return self._cell.solve(self._to[arm], *args)

    def trajectory(self, arm, *args, **kwargs):
        return self._cell.trajectory(self._to[arm], *args, **kwargs)

    def grip(self, arm, on):
        return self._cell.grip(self._to[arm], on)

    def step(self):
        obs = self._cell.step()
        return dataclasses.replace(
            obs, arms={self._back[k]: v for k, v in obs.arms.items()},
            bases={self._back[k]: v for k, v in obs.bases.items()})


def test_a_trial_starts_the_ik_servers_in_the_robots_namespaces(tmp_path):
    world = tmp_path / 'renamed.yaml'
    world.write_text(yaml.safe_dump(renamed()))
    nodes = {n.name: n for n in pipeline_graph(1, 0.05, world=str(world))}
    assert nodes['arm_kinematics'].namespace == 'cell_arm'
    assert nodes['carrier_kinematics'].namespace == 'cell_carrier'
    # (Each IK server reads its arm's model from the world: the robot named there.)
    assert nodes['arm_kinematics'].parameters['arm'] == 'arm'
    assert nodes['arm_kinematics'].parameters['world'] == str(world)
    assert nodes['carrier_kinematics'].parameters['frame_prefix'] == 'cell_carrier/'


@pytest.mark.parametrize('cell, why', [
    ({'loader': 'carrier', 'transports': ['arm']}, "cell.loader 'carrier' must be a fixed arm"),
    ({'loader': 'arm', 'transports': ['ghost']}, "cell.transports 'ghost' is not a robot"),
    ({'loader': 'arm', 'transports': ['arm']}, "cell.transports 'arm' must be a mobile robot"),
    ({'loader': 'arm', 'transports': []}, 'cell.transports must be a list of robot names'),
    ({'loader': 'arm', 'transports': ['carrier', 'carrier']}, 'names each robot once'),
    ({'loader': 'arm', 'transport': ['carrier']}, 'transport'),
])
def test_roles_that_cannot_be_are_refused_in_one_line(cell, why):
    data = renamed()
    data['cell'] = cell
    with pytest.raises(WorldConfigError, match=why) as err:
        parse_world(data)
    assert '\n' not in str(err.value)


def test_what_the_controller_cannot_drive_is_refused_at_start_up_in_one_line():
    # The paper's names gone, and no cell section naming the new ones.
    with pytest.raises(LayoutError, match=r"needs its loader zu12 and transports \['youbot'\]"):
        layout_from_world(parse_world(renamed(cell=False)))
    # A second transport robot, and no loading pose apart from their start poses.
    data = renamed()
    data['robots'].append(copy.deepcopy(data['robots'][1]))
    data['robots'][-1].update(name='carrier2', namespace='cell_carrier2',
                              frame_prefix='cell_carrier2/')
    data['robots'][-1]['pose']['y'] -= 1.0         # (clear of the belt, north of the youBot)
    data['cell']['transports'].append('carrier2')
    with pytest.raises(LayoutError, match='gives the loading pose'):
        layout_from_world(parse_world(data))
    # An arm controller that drives other joints than the arm it knows.
    data = renamed()
    data['robots'][0]['controllers'][0]['joints'] = data['robots'][0]['controllers'][0][
        'joints'][:5]
    with pytest.raises(LayoutError, match=r"robot arm: .*zu12.urdf: joints \['joint_6'\] move "
                                          'suction_tcp but are not among the arm'):
        layout_from_world(parse_world(data))
