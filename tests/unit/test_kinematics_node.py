"""The kinematics node in-process: malformed joint states are ignored with a warning, the pose
follows good ones, configuration errors stop it at start-up, and a motion request it cannot
send is refused with the reason (the node goes on)."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from arm_kinematics.kinematics_node import KinematicsConfigError, KinematicsNode
from controllers.transforms import matrix_to_quaternion
from controllers.youbot_arm import JOINT_NAMES


def test_malformed_joint_states_are_ignored(context):
    node = KinematicsNode(context=context)
    published = []
    node._pose_pub.publish = published.append
    node._pose_pub.get_subscription_count = lambda: 1       # (a reader of the pose)
    try:
        node._on_joint_states(JointState(name=list(JOINT_NAMES), position=[0.0, 0.1]))
        node._on_joint_states(JointState(name=list(JOINT_NAMES),
                                         position=[math.nan, 0.0, 0.0, 0.0, 0.0]))
        node._on_joint_states(JointState(name=['other'], position=[1.0]))
        assert published == [] and node._positions is None
        node._on_joint_states(JointState(name=list(JOINT_NAMES), position=[0.0] * 5))
        assert len(published) == 1
        assert published[0].pose.position.z == pytest.approx(0.014 + 0.55 + 0.1046)
        # Nobody reads the pose: the positions are kept, no FK is done and nothing is sent.
        node._pose_pub.get_subscription_count = lambda: 0
        node._on_joint_states(JointState(name=list(JOINT_NAMES), position=[0.1] * 5))
        assert len(published) == 1 and node._positions[0] == 0.1
    finally:
        node.destroy_node()


@pytest.mark.parametrize('overrides, fragment', [
    ([Parameter('arm', value='ur5')], 'arm "ur5" unknown: the world .* has'),
    ([Parameter('tool_frame', value='elbow')], 'no link "elbow"'),
    ([Parameter('world', value='/nonexistent/world.yaml')], 'world /nonexistent/world.yaml'),
])
def test_bad_parameters_stop_it_at_start_up(context, overrides, fragment):
    with pytest.raises(KinematicsConfigError, match=fragment):
        KinematicsNode(context=context, parameter_overrides=overrides)


def _target_of(node, q) -> PoseStamped:
    pose = node._kin.fk(np.asarray(q, float))
    msg = PoseStamped()
    msg.header.frame_id = 'base_link'
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = pose[:3, 3].tolist()
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(pose[:3, :3])
    return msg


@pytest.mark.parametrize('duration, scaling, fragment', [
    (1.0e300, 0.0, 'bad duration'),                 # (crashed the node: an int overflow)
    (math.inf, 0.0, 'bad duration'),
    (0.0, 1.0e-300, 'would take'),                  # (crashed it too: a C long overflow)
    (1.0e-9, 0.0, 'too short'),                     # (was "success"; the simulator refused)
])
def test_a_motion_request_it_cannot_send_is_refused_and_the_node_goes_on(
        context, duration, scaling, fragment):
    node = KinematicsNode(context=context)
    sent = []
    node._traj_pub.publish = sent.append
    try:
        node._positions = np.zeros(5)
        target = _target_of(node, [0.3, 0.4, -0.5, 0.2, 0.1])
        ok, message, _, _, _ = node._solve(target, True, duration, scaling)
        assert not ok and fragment in message and sent == []
        # The same node still answers a good request.
        ok, message, positions, _, trajectory = node._solve(target, True, 0.0, 0.0)
        assert ok and len(sent) == 1
        assert np.allclose(node._kin.fk(positions), node._kin.fk([0.3, 0.4, -0.5, 0.2, 0.1]))
    finally:
        node.destroy_node()
