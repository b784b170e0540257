"""The kinematics node in-process: malformed joint states are ignored with a warning, the pose
follows good ones, and configuration errors stop it at start-up."""
import math

import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from arm_kinematics.kinematics_node import KinematicsConfigError, KinematicsNode
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
    ([Parameter('arm', value='ur5')], 'arm "ur5" unknown'),
    ([Parameter('tool_frame', value='elbow')], 'unknown tool frame'),
    ([Parameter('arm', value='zu12'), Parameter('base_pose', value=[0.0, 1.0])],
     'base_pose must be 4'),
])
def test_bad_parameters_stop_it_at_start_up(context, overrides, fragment):
    with pytest.raises(KinematicsConfigError, match=fragment):
        KinematicsNode(context=context, parameter_overrides=overrides)
