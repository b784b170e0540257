"""The names a world's graph makes (world_description.graph_names), held to a running graph: the
trial graph of a cell with its robots under other names, started as run_trials starts it; every
node, topic and service it has must be in the table the world's start-up check refuses clashes
by, or a clash could pass unseen."""
from typing import Set, Tuple

import numpy as np
import pytest
import yaml
from sensor_msgs.msg import JointState

from helpers import stamp_s, wait_for
from studies.trial_graph import pipeline_graph
from world_description.graph_names import graph_names
from world_description.resources import resolve_resource
from world_description.world_config import load_world


@pytest.fixture
def renamed_world(tmp_path):
    """The paper's cell, its robots named and spaced as a user's cell would be."""
    data = yaml.safe_load(resolve_resource(
        'package://world_description/worlds/pipeline_cell.yaml').read_text())
    for robot, name in zip(data['robots'], ('picker', 'carrier')):
        robot.update(name=name, namespace=f'line_a/{name}', frame_prefix=f'{name}/')
    data['robots'][1]['suction']['service'] = 'hand/grasp'
    data['cell'] = {'loader': 'picker', 'transports': ['carrier']}
    # (A conveyor drive with an encoder: its topic, and the coordinator's subscription.)
    data['conveyor']['encoder'] = {'resolution': 1.0e-4, 'noise': 0.001}
    path = tmp_path / 'renamed.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def _live(node) -> Set[Tuple[str, str]]:
    names = {('topic', t) for t, _ in node.get_topic_names_and_types()}
    names |= {('service', s) for s, _ in node.get_service_names_and_types()}
    names |= {('node', f'{ns.rstrip("/")}/{n}') for n, ns in
              node.get_node_names_and_namespaces()}
    return names


def test_every_name_of_a_running_graph_is_in_the_worlds_table(renamed_world, start_node, probe):
    world = str(renamed_world)
    for node in pipeline_graph(5, 0.1, synchronous=False, world=world, real_time_factor=1.0):
        start_node(node.executable, *node.ros_args()[1:], name=node.name)
    table = {(n.kind, n.name) for n in graph_names(load_world(world))}
    own = f'/{probe.node.get_name()}'
    expected = {('service', '/sim_node/reset'), ('service', '/line_a/picker/solve_ik'),
                ('service', '/line_a/carrier/hand/grasp'), ('topic', '/coordinator_node/events'),
                ('topic', '/detections'), ('node', '/line_a/carrier/kinematics_node'),
                ('topic', '/conveyor/joint_states')}
    wait_for(lambda: expected <= _live(probe.node), 90.0, period=0.5,
             what='every node of the graph to be discovered')
    # (Discovery brings a node's names in bursts: the set is read until two readings a second
    # apart agree.)
    seen: Set[Tuple[str, str]] = set()

    def settled() -> bool:
        nonlocal seen
        now = _live(probe.node)
        same, seen = now == seen, now
        return same
    wait_for(settled, 60.0, period=1.0, what='the graph\'s names to settle')
    unknown = sorted(n for n in seen - table
                     if not n[1].startswith(own) and n[1] not in (own,))
    assert unknown == [], unknown
    # And the table is the graph's, not a list of every name there could be: most of it runs.
    robots = {n for n in table if '/line_a/' in n[1]}
    assert len(robots & seen) >= 0.8 * len(robots), sorted(robots - seen)
    # The encoder counts the belt's travel in whole counts, and reads the belt's set speed
    # while it runs.
    readings = probe.collect(JointState, '/conveyor/joint_states')
    wait_for(lambda: len(readings) >= 60, 60.0, what="the belt encoder's readings")
    msgs = [m for _, m in list(readings)]
    assert all(m.name == ['belt'] for m in msgs)
    assert all(abs(m.position[0] / 1e-4 - round(m.position[0] / 1e-4)) < 1e-6 for m in msgs)
    moving = [(b.position[0] - a.position[0]) / (stamp_s(b.header.stamp)
                                                 - stamp_s(a.header.stamp))
              for a, b in zip(msgs, msgs[1:]) if b.position[0] > a.position[0]]
    set_speed = yaml.safe_load(renamed_world.read_text())['conveyor']['belt_speed']
    assert len(moving) >= 10 and float(np.median(moving)) == pytest.approx(set_speed, rel=0.05)
