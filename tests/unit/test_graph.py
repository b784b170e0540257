"""The pipeline run's node graph, described once (studies.trial_graph)."""
from pathlib import Path

import pytest
import yaml

from studies.trial_graph import (
    TIME_STEP,
    GraphNode,
    parameter_text,
    pipeline_graph,
    tick_rate,
)
from world_description import PIPELINE_CELL


def test_a_lock_step_trial_is_five_processes_that_agree_on_the_scenario():
    graph = pipeline_graph(7, 0.13, world=PIPELINE_CELL, result_file='/r/result.json')
    assert [n.name for n in graph] == ['sim_node', 'vision_node', 'zu12_kinematics',
                                       'youbot_kinematics', 'coordinator_node']
    by = {n.name: n for n in graph}
    sim, coordinator = by['sim_node'].parameters, by['coordinator_node'].parameters
    for key in ('scenario_seed', 'belt_speed', 'world', 'synchronous'):
        assert sim[key] == coordinator[key], key
    assert sim['synchronous'] is True and sim['clock_publish_rate'] == tick_rate(TIME_STEP)
    assert sim['time_step'] == coordinator['time_step'] == TIME_STEP
    assert coordinator['result_file'] == '/r/result.json'
    # In lock-step no node reads /clock: the simulator is its source, the vision node and the
    # IK servers read none, and the coordinator keeps the step count's time (a /clock
    # subscription would only cost them CPU). In real time the coordinator follows it.
    assert not any('use_sim_time' in n.parameters for n in graph)
    real_time = {n.name: n.parameters
                 for n in pipeline_graph(7, 0.13, synchronous=False, world=PIPELINE_CELL)}
    assert real_time['coordinator_node']['use_sim_time'] is True
    assert not any('use_sim_time' in real_time[name] for name in real_time
                   if name != 'coordinator_node')
    # The IK servers take no joint_states: every request the coordinator makes is seeded.
    assert by['zu12_kinematics'].parameters['track_joint_states'] is False
    assert by['youbot_kinematics'].parameters['track_joint_states'] is False
    assert (by['zu12_kinematics'].namespace, by['youbot_kinematics'].namespace) == (
        'zu12', 'youbot')
    # The IK servers name their frames as the simulator does: the world's frame prefixes.
    assert by['zu12_kinematics'].parameters['frame_prefix'] == 'zu12/'
    assert by['youbot_kinematics'].parameters['frame_prefix'] == 'youbot/'


@pytest.mark.parametrize('time_step, steps', [(1.0 / 240.0, 8), (1.0 / 120.0, 4), (0.01, 3)])
def test_lock_step_states_fall_on_the_tick_at_any_physics_step(time_step, steps):
    """The simulator counts whole nanoseconds per step: at 1/120 s, 4 steps are 33333332 ns,
    and states every round(1e9 / 30) ns would come a step late, past the tick the coordinator
    waits for (it refused to start). The graph gives both the tick's own rate."""
    graph = {n.name: n.parameters for n in pipeline_graph(0, 0.12, time_step=time_step)}
    sim, coordinator = graph['sim_node'], graph['coordinator_node']
    dt_ns = round(time_step * 1e9)
    state_ns = round(1e9 / sim['state_publish_rate'])
    assert state_ns == steps * dt_ns == round(1e9 / sim['clock_publish_rate'])
    # The coordinator's own check (coordinator_node: lock-step needs states on its ticks).
    ticks = max(1, round(1e9 / coordinator['control_rate'] / round(coordinator['time_step']
                                                                    * 1e9)))
    assert ticks == steps and round(1e9 / coordinator['state_publish_rate']) <= ticks * dt_ns


def test_real_time_publishes_the_clock_at_every_step_and_a_recorder_starts_first():
    graph = pipeline_graph(0, 0.12, synchronous=False, real_time_factor=2.0,
                           record_dir='/bags', bag_name=None)
    assert graph[0].name == 'recorder' and 'bag_name' not in graph[0].parameters
    sim = next(n for n in graph if n.name == 'sim_node').parameters
    assert sim['clock_publish_rate'] == 0.0 and sim['real_time_factor'] == 2.0
    # The belt stands until the coordinator, with its graph up, starts it at the run's speed.
    coordinator = next(n for n in graph if n.name == 'coordinator_node').parameters
    assert sim['belt_speed'] == 0.0 and coordinator['belt_speed'] == 0.12
    assert '/belt_camera/image_raw' in graph[0].parameters['exclude']


def test_command_lines_are_what_ros2_run_takes():
    node = GraphNode('k', 'arm_kinematics', 'kinematics_node', namespace='zu12',
                     parameters={'arm': 'zu12', 'use_sim_time': True, 'rate': 30.0,
                                 'exclude': ['/a', '/b']},
                     remappings=(('image_raw', '/cam/image_raw'),))
    assert node.command() == [
        'kinematics_node', '--ros-args', '-r', '__ns:=/zu12', '-r', 'image_raw:=/cam/image_raw',
        '-p', 'arm:=zu12', '-p', 'use_sim_time:=true', '-p', 'rate:=30.0', '-p',
        "exclude:=['/a', '/b']"]
    assert parameter_text(False) == 'false' and parameter_text(3) == '3'
    # Any text in a list goes through YAML (rcl's parser) as it was: quotes, backslashes, JSON.
    items = ['k={"a": "it\'s", "b": "c:\\\\d"}', "'", '', 'x, y', '[1]']
    assert yaml.safe_load(parameter_text(items)) == items


def test_a_recorded_trial_keeps_what_ran_in_its_bag():
    graph = pipeline_graph(7, 0.13, world=PIPELINE_CELL, record_dir=Path('/r'),
                           bag_metadata={'robot_sim.trial': '{"seed": 7}'})
    recorder = next(n for n in graph if n.name == 'recorder')
    assert recorder.parameters['custom_data'] == ['robot_sim.trial={"seed": 7}']


def test_run_trials_refuses_a_physics_step_longer_than_a_control_tick(capsys):
    from studies.run_trials import main
    assert main(['--time-step', '0.05', '--out', '/nonexistent/never-made', '--show-graph']) == 2
    assert 'time_step must be within' in capsys.readouterr().err
