"""Conversions between the simulator's state (ROS-free: world, runner, frames) and ROS
messages, for ``sim_node`` and the trajectory action servers. No node state here: each
function builds one message (or request) from its arguments."""
from __future__ import annotations

from typing import Sequence, Tuple

from builtin_interfaces.msg import Time
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTrajectoryControllerState
from geometry_msgs.msg import TransformStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, JointState
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker

from controllers.joint_trajectory import TrajectoryPoint, TrajectoryRequest
from controllers.transforms import matrix_to_quaternion
from ros_common.stamps import to_seconds
from sim_bridge.frames import FrameTransform

# Ground truth: tiny but non-zero covariance (zero often reads as "unknown").
GROUND_TRUTH_COVARIANCE = [1e-9 if i % 7 == 0 else 0.0 for i in range(36)]


def topic(namespace: str, name: str) -> str:
    """A robot's topic: relative, so that a node namespace or a remapping applies on top."""
    return f'{namespace}/{name}' if namespace else name


def trajectory_request(msg: JointTrajectory) -> TrajectoryRequest:
    """A JointTrajectory as the follower takes it (a zero stamp means "start now")."""
    stamp = msg.header.stamp
    start = None if stamp.sec == 0 and stamp.nanosec == 0 else to_seconds(stamp)
    points = tuple(TrajectoryPoint(to_seconds(p.time_from_start), tuple(p.positions),
                                   tuple(p.velocities), tuple(p.accelerations), tuple(p.effort))
                   for p in msg.points)
    return TrajectoryRequest(tuple(msg.joint_names), points, start)


def twist_values(msg) -> Tuple[float, ...]:
    """The six numbers of a Twist or TwistStamped: linear x, y, z, angular x, y, z."""
    t = msg.twist if isinstance(msg, TwistStamped) else msg
    return (t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z)


def twist_stamp(msg):
    """A TwistStamped's stamp in seconds; None for a Twist or an unset stamp ("now", as
    diff_drive_controller reads it)."""
    if not isinstance(msg, TwistStamped):
        return None
    stamp = msg.header.stamp
    return to_seconds(stamp) if (stamp.sec or stamp.nanosec) else None


def applied_twist(command: Sequence[float], frame: str, stamp: Time) -> TwistStamped:
    """diff_drive_controller's cmd_vel_out: the (vx, vy, wz) the wheels follow."""
    msg = TwistStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z = (float(v) for v in command)
    return msg


def joint_state(js, stamp: Time) -> JointState:
    msg = JointState(name=js.names, position=js.positions, velocity=js.velocities,
                     effort=js.efforts)
    msg.header.stamp = stamp
    return msg


def odometry(base, frames: Tuple[str, str], stamp: Time) -> Odometry:
    """A base's ground-truth odometry (``frames``: odom and base_link, prefixed)."""
    odom = Odometry()
    odom.header.stamp = stamp
    odom.header.frame_id, odom.child_frame_id = frames
    pose, twist = odom.pose.pose, odom.twist.twist
    pose.position.x, pose.position.y, pose.position.z = base.position
    (pose.orientation.x, pose.orientation.y, pose.orientation.z,
     pose.orientation.w) = base.orientation
    twist.linear.x, twist.linear.y, twist.linear.z = (float(v) for v in base.linear)
    twist.angular.x, twist.angular.y, twist.angular.z = (float(v) for v in base.angular)
    odom.pose.covariance = GROUND_TRUTH_COVARIANCE
    odom.twist.covariance = GROUND_TRUTH_COVARIANCE
    return odom


def camera_info(config, intrinsics) -> CameraInfo:
    """A pinhole camera's calibration, without distortion."""
    info = CameraInfo(height=config.height, width=config.width, distortion_model='plumb_bob',
                      d=[0.0] * 5, k=list(intrinsics.k),
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], p=list(intrinsics.p))
    info.header.frame_id = config.frame_id
    return info


def transform(t: FrameTransform, stamp: Time) -> TransformStamped:
    out = TransformStamped()
    out.header.stamp = stamp
    out.header.frame_id, out.child_frame_id = t.parent, t.child
    tr, q = out.transform.translation, out.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in t.translation)
    q.x, q.y, q.z, q.w = (float(v) for v in t.rotation)
    return out


def fill_points(reference_point, feedback_point, error_point, reference, position,
                velocity) -> None:
    """A joint group's reference, feedback and their difference into three
    trajectory_msgs/JointTrajectoryPoint (what JTC's state and feedback carry)."""
    reference_point.positions = reference.positions.tolist()
    reference_point.velocities = reference.velocities.tolist()
    feedback_point.positions = position.tolist()
    feedback_point.velocities = velocity.tolist()
    error_point.positions = (reference.positions - position).tolist()
    error_point.velocities = (reference.velocities - velocity).tolist()


def controller_state(group, stamp: Time) -> JointTrajectoryControllerState:
    """control_msgs' state of a joint trajectory controller. reference and feedback are
    repeated in the deprecated desired and actual (Jazzy's JTC fills both)."""
    desired = group.desired
    position, velocity = group.actual()
    msg = JointTrajectoryControllerState(joint_names=list(group.joint_names))
    msg.header.stamp = stamp
    fill_points(msg.reference, msg.feedback, msg.error, desired, position, velocity)
    msg.reference.accelerations = desired.accelerations.tolist()
    msg.output.positions = desired.positions.tolist()
    msg.output.effort = group.limits.effort.tolist()
    msg.desired, msg.actual = msg.reference, msg.feedback
    return msg


def trajectory_feedback(stamp: Time, joint_names, reference, position,
                        velocity) -> FollowJointTrajectory.Feedback:
    """FollowJointTrajectory's feedback of a joint group: desired, actual, error."""
    fb = FollowJointTrajectory.Feedback(joint_names=list(joint_names))
    fb.header.stamp = stamp
    fill_points(fb.desired, fb.actual, fb.error, reference, position, velocity)
    return fb


def material_marker(material, pos, rot, state: str, config, stamp: Time) -> Marker:
    """A material's ground truth on /cell/materials: its pose, size, colour; ``state`` (held,
    on_belt, free) in the text."""
    marker = Marker(ns=material.color, id=material.index, type=Marker.CUBE,
                    action=Marker.ADD, text=state)
    marker.header.stamp = stamp
    marker.header.frame_id = 'world'
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (
        float(v) for v in pos)
    o = marker.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(rot)
    marker.scale.x = marker.scale.y = marker.scale.z = material.size
    r, g, b, a = dict(config.colors)[material.color]
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = r, g, b, a
    return marker
