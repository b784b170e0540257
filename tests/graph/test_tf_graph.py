"""TF from the simulator as tf2 and RViz take it: /tf_static latched, /tf at the state rate,
one tree under ``world`` with every robot's frames prefixed, each robot's description, and an
arm driven through FollowJointTrajectory moving its frames. Standard messages only."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Dict, List, Set

import pytest
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectoryPoint

from helpers import ActionUser, wait_for
from world_description import PIPELINE_CELL

# tf2's own subscriptions: /tf_static transient local (it is published once), /tf volatile.
STATIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)

CELL_CHAINS = [
    ['world', 'youbot/odom', 'youbot/base_link', 'youbot/arm_link_0', 'youbot/arm_link_1',
     'youbot/arm_link_2', 'youbot/arm_link_3', 'youbot/arm_link_4', 'youbot/arm_link_5',
     'youbot/gripper_palm_link', 'youbot/gripper_tcp'],
    ['youbot/base_link', 'youbot/wheel_link_fl'],
    ['world', 'zu12/base_link', 'zu12/link_1', 'zu12/link_2', 'zu12/link_3', 'zu12/link_4',
     'zu12/link_5', 'zu12/link_6', 'zu12/flange', 'zu12/suction_tool', 'zu12/suction_tcp'],
    ['world', 'belt_camera_optical_frame'],
]


def _edges(batches: List) -> Dict[str, str]:
    """child: parent, over every TFMessage received."""
    out: Dict[str, str] = {}
    for _, msg in batches:
        for t in msg.transforms:
            assert out.get(t.child_frame_id, t.header.frame_id) == t.header.frame_id, \
                f'{t.child_frame_id} has two parents'
            out[t.child_frame_id] = t.header.frame_id
    return out


def _cell(start_node, probe, *args):
    static = probe.collect(TFMessage, '/tf_static', STATIC_QOS)
    probe.descriptions = {ns: probe.collect(String, f'/{ns}/robot_description', STATIC_QOS)
                          for ns in ('youbot', 'zu12')}
    moving = probe.collect(TFMessage, '/tf', TF_QOS)
    start_node('sim_node', '-p', f'world:={PIPELINE_CELL}', '-p', 'real_time_factor:=2.0',
               '-p', 'state_publish_rate:=30.0', *args)
    wait_for(lambda: static, 20.0, what='/tf_static')
    # Both robots' moving frames, a few times over.
    wait_for(lambda: len(moving) >= 10, 20.0, what='/tf')
    return static, moving


def test_the_cell_is_one_tf_tree_and_an_arm_moves_on_its_action(start_node, probe):
    static, moving = _cell(start_node, probe)
    assert len(static) == 1          # published once, latched
    edges = _edges(static + moving)
    for chain in CELL_CHAINS:
        for parent, child in zip(chain, chain[1:]):
            assert edges.get(child) == parent, f'{parent} -> {child} missing'
    roots: Set[str] = set(edges.values()) - set(edges)
    assert roots == {'world'}
    static_children = {t.child_frame_id for t in static[0][1].transforms}
    assert {'youbot/odom', 'zu12/base_link', 'zu12/suction_tcp', 'youbot/gripper_tcp',
            'belt_camera_optical_frame'} <= static_children
    moving_children = {t.child_frame_id for _, m in moving for t in m.transforms}
    assert {'youbot/base_link', 'zu12/link_1', 'youbot/arm_link_1'} <= moving_children
    assert not moving_children & static_children
    # Each robot's description, latched, draws it from the frames of the tree.
    for ns, received in probe.descriptions.items():
        wait_for(lambda received=received: received, 10.0, what=f'/{ns}/robot_description')
        links = {link.get('name') for link in ET.fromstring(received[0][1].data).iter('link')}
        assert links and all(link.startswith(f'{ns}/') for link in links)
        assert links <= set(edges) | {'world'}
    # Stamped with simulated time, which advances.
    stamps = sorted({(t.header.stamp.sec, t.header.stamp.nanosec)
                     for _, m in moving for t in m.transforms})
    assert len(stamps) >= 3
    # The Zu 12 driven through its FollowJointTrajectory action: joint_1 turns 0.3 rad, and
    # so does zu12/link_1's transform in /tf.
    joints = probe.collect(JointState, '/zu12/joint_states')
    wait_for(lambda: joints, 10.0, what='/zu12/joint_states')
    start = dict(zip(joints[-1][1].name, joints[-1][1].position))
    before = _rotation(moving, 'zu12/link_1')
    names = [f'joint_{i}' for i in range(1, 7)]
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = names
    target = [start[n] + (0.3 if n == 'joint_1' else 0.0) for n in names]
    goal.trajectory.points = [JointTrajectoryPoint(positions=target)]
    goal.trajectory.points[0].time_from_start.sec = 2
    goal.goal_tolerance = [JointTolerance(name=n, position=0.02) for n in names]
    goal.goal_time_tolerance.sec = 2
    arm = ActionUser('/zu12/arm_controller/follow_joint_trajectory')
    try:
        arm.ready(30.0)
        handle = arm.send(goal)
        assert handle.accepted
        done = arm.result(handle)
    finally:
        arm.close()
    assert done.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, \
        done.result.error_string
    # The arm is at rest at its goal: /tf comes to show joint_1's turn (on a loaded machine the
    # transforms of the motion, sent before the result, may still be arriving).
    moving.clear()
    wait_for(lambda: len(moving) >= 3 and _angle_between(
        before, _rotation(moving, 'zu12/link_1')) == pytest.approx(0.3, abs=0.03), 20.0,
        what="/tf to show zu12/link_1 turned by joint_1's 0.3 rad")
    turned = _angle_between(before, _rotation(moving, 'zu12/link_1'))
    assert turned == pytest.approx(0.3, abs=0.03)


def _rotation(batches: List, child: str):
    r = next(t.transform.rotation for _, m in reversed(batches) for t in m.transforms
             if t.child_frame_id == child)
    return (r.x, r.y, r.z, r.w)


def _angle_between(a, b) -> float:
    dot = abs(sum(x * y for x, y in zip(a, b)))
    return 2.0 * math.acos(min(1.0, dot))


def test_without_link_tf_only_odometry_and_the_anchors_are_published(start_node, probe):
    static, moving = _cell(start_node, probe, '-p', 'publish_link_tf:=false')
    assert {t.child_frame_id for t in static[0][1].transforms} == {
        'youbot/odom', 'zu12/base_link', 'belt_camera_optical_frame'}
    assert {(t.header.frame_id, t.child_frame_id) for _, m in moving for t in m.transforms} \
        == {('youbot/odom', 'youbot/base_link')}


def test_a_recorded_bag_of_the_cell_decodes_with_an_independent_reader(start_node, probe,
                                                                       tmp_path):
    """The recorder's MCAP (zstd chunks) read with the mcap library and its ROS 2 decoder,
    which share no code with rosbags: the TF tree, both descriptions and the camera frames."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    start_node('sim_node', '-p', f'world:={PIPELINE_CELL}', '-p', 'real_time_factor:=2.0',
               '-p', 'state_publish_rate:=30.0')
    rec = start_node('recorder', '-p', f'output_dir:={tmp_path}', '-p', 'bag_name:=cell',
                     '-p', 'compression:=zstd', name='recorder')
    for topic in ('/tf', '/tf_static', '/youbot/robot_description',
                  '/zu12/robot_description', '/belt_camera/image_raw'):
        wait_for(lambda t=topic: f'receiving {t}\n' in rec.output(), 30.0,
                 what=f'the recorder to receive {topic}')
    # Each robot's moving frames come in a /tf message of their own: recorded until both have
    # come a few times over (stopped at the first /tf, under load the bag held the Zu 12's
    # frames only).
    moving = probe.collect(TFMessage, '/tf', TF_QOS)
    wait_for(lambda: len(moving) >= 10, 30.0, what='/tf, both robots')
    assert rec.stop() == 0
    assert 'zstd compression' in rec.output()
    (path,) = (tmp_path / 'cell').glob('*.mcap')
    seen: Dict[str, List] = {}
    with path.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        chunks = reader.get_summary().chunk_indexes
        for _, channel, _, msg in reader.iter_decoded_messages():
            seen.setdefault(channel.topic, []).append(msg)
    assert chunks and {c.compression for c in chunks} == {'zstd'}
    edges = {t.child_frame_id: t.header.frame_id
             for topic in ('/tf', '/tf_static') for m in seen[topic] for t in m.transforms}
    for chain in CELL_CHAINS:
        for parent, child in zip(chain, chain[1:]):
            assert edges.get(child) == parent, f'{parent} -> {child} missing'
    for ns in ('youbot', 'zu12'):
        (description,) = seen[f'/{ns}/robot_description']
        assert ET.fromstring(description.data).find('link').get('name').startswith(f'{ns}/')
    frame = seen['/belt_camera/image_raw'][0]
    assert (frame.width, frame.height, frame.encoding) == (320, 240, 'rgb8')
    assert len(frame.data) == 320 * 240 * 3
