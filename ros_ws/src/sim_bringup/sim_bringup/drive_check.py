"""Compare a base's final odometry with the pose the kinematics predicts for a teleop script.

The teleop runs its script open loop, and on a busy machine its commands take effect a little
late: the simulator, catching up with the wall clock, runs a few steps before it reads a new
command. The check therefore predicts from the commands as the simulator applied them, stamped
when each took effect (its ``cmd_vel_out``, like diff_drive_controller's), and prints the
script's own prediction beside it.
"""
from __future__ import annotations

import math
import sys
import time
from typing import List, Optional, Tuple

import rclpy
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile

from controllers.diff_drive import Pose2D, predict_pose, wrap_angle
from controllers.transforms import yaw_from_quaternion
from ros_common.node_main import run_task
from ros_common.params import Param, declare_params
from ros_common.stamps import to_seconds
from teleop.teleop_core import TeleopError, parse_script

PARAMS = (
    Param('script', '', 'The teleop script being driven (same syntax as teleop)'),
    Param('max_speed', 0.2, 'The simulator limit and teleop max_speed [m/s]', 1e-3, 10.0),
    Param('max_turn', 0.2, 'The simulator limit and teleop max_turn [rad/s]', 1e-3, 20.0),
    Param('speed', 0.5, 'The teleop initial speed level', 0.0, 1.0),
    Param('position_tolerance', 0.05, 'Pass limit [m]', 0.0, 10.0),
    Param('yaw_tolerance', 0.1, 'Pass limit [rad]', 0.0, 3.2),
    Param('settle_time', 1.0, 'Done when no cmd_vel came for this long [s] and the base is at '
          'rest', 0.1, 60.0),
    Param('wall_timeout', 300.0, 'Give up after [wall s]', 1.0, 3600.0),
)


class DriveCheck(Node):
    """Knows the script the teleop runs; listens to ``cmd_vel`` and ``odom``.

    Once commands have ended (the last one zero, none for ``settle_time``) and the base is at
    rest, it reports the final odometry pose against the pose that integrating the commands the
    simulator applied (``cmd_vel_out``) predicts; and the script's own prediction (its twists,
    clamped to the simulator's limits, for exactly their durations).
    """

    def __init__(self, **kwargs) -> None:
        super().__init__('drive_check', **kwargs)
        p = declare_params(self, PARAMS)
        max_speed, max_turn = p['max_speed'], p['max_turn']
        script = parse_script(p['script'], max_speed, max_turn, p['speed'])
        segments = [(max(-max_speed, min(max_speed, s.v)), max(-max_turn, min(max_turn, s.w)),
                     s.duration) for s in script.steps]
        self.predicted = predict_pose(Pose2D(), segments)
        # (simulated time it took effect, v, w), as the simulator says
        self._applied: List[Tuple[float, float, float]] = []
        self.wall_timeout = p['wall_timeout']
        self._tol = (p['position_tolerance'], p['yaw_tolerance'])
        self._settle = p['settle_time']
        self._moving = False
        self._last_cmd: Optional[Tuple[float, bool]] = None   # (sim time, was it zero)
        self._odom: Optional[Odometry] = None
        self.result: Optional[bool] = None
        reliable = QoSProfile(depth=10)
        self.create_subscription(Twist, 'cmd_vel', self._on_cmd, reliable)
        self.create_subscription(Odometry, 'odom', self._on_odom, reliable)
        self.create_subscription(TwistStamped, 'cmd_vel_out', self._on_applied, QoSProfile(
            depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.get_logger().info(
            f'waiting for commands on cmd_vel and odometry on odom; the script of '
            f'{len(segments)} steps should end at x={self.predicted.x:+.4f} m '
            f'y={self.predicted.y:+.4f} m yaw={math.degrees(self.predicted.yaw):+.2f} deg')

    def _on_applied(self, msg: TwistStamped) -> None:
        t = to_seconds(msg.header.stamp)
        self._applied.append((t, msg.twist.linear.x, msg.twist.angular.z))

    def _on_cmd(self, msg: Twist) -> None:
        is_zero = msg.linear.x == 0.0 and msg.angular.z == 0.0
        self._moving = self._moving or not is_zero
        self._last_cmd = (self.get_clock().now().nanoseconds * 1e-9, is_zero)

    def _on_odom(self, msg: Odometry) -> None:
        self._odom = msg
        last = self._last_cmd
        if self.result is not None or not self._moving or last is None or not last[1]:
            return
        t = to_seconds(msg.header.stamp)
        twist = msg.twist.twist
        if (t - last[0] > self._settle and abs(twist.linear.x) < 1e-3
                and abs(twist.angular.z) < 1e-3):
            self.result = self._report(msg)

    def as_applied(self, until: float) -> Pose2D:
        """The pose the applied commands predict, each from when it took effect until the
        next (the last until ``until``)."""
        applied = sorted(self._applied)
        ends = [t for t, _, _ in applied[1:]] + [until]
        return predict_pose(Pose2D(), [(v, w, max(0.0, end - t))
                                       for (t, v, w), end in zip(applied, ends)])

    def _report(self, odom: Odometry) -> bool:
        p = odom.pose.pose
        actual = Pose2D(p.position.x, p.position.y, yaw_from_quaternion(
            (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)))
        script = self.predicted
        self.get_logger().info(
            f'the script predicted:  x={script.x:+.4f} m  y={script.y:+.4f} m  '
            f'yaw={math.degrees(script.yaw):+7.2f} deg (as timed, had the teleop switched '
            'exactly on time)')
        if self._applied:
            stamp = odom.header.stamp
            predicted = self.as_applied(to_seconds(stamp))
            basis = f'for the {len(self._applied)} commands as the simulator applied them'
        else:
            self.get_logger().warn('nothing on cmd_vel_out (a simulator without it?): '
                                   'judging by the script alone')
            predicted, basis = script, 'for the script'

        dpos = math.hypot(actual.x - predicted.x, actual.y - predicted.y)
        dyaw = wrap_angle(actual.yaw - predicted.yaw)
        ok = dpos <= self._tol[0] and abs(dyaw) <= self._tol[1]
        log = self.get_logger().info if ok else self.get_logger().error
        log(f'final pose from odom:  x={actual.x:+.4f} m  y={actual.y:+.4f} m  '
            f'yaw={math.degrees(actual.yaw):+7.2f} deg')
        log(f'kinematics predicted:  x={predicted.x:+.4f} m  y={predicted.y:+.4f} m  '
            f'yaw={math.degrees(predicted.yaw):+7.2f} deg ({basis})')
        log(f'error: position {dpos * 1000:.1f} mm (limit {self._tol[0] * 1000:.0f}), '
            f'yaw {math.degrees(dyaw):+.2f} deg (limit {math.degrees(self._tol[1]):.1f}) -> '
            + ('PASS' if ok else 'FAIL'))
        return ok


def _check(node: 'DriveCheck') -> int:
    deadline = time.monotonic() + node.wall_timeout
    while rclpy.ok() and node.result is None and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    if node.result is None and not rclpy.ok():
        node.get_logger().info('stopped before the drive ended: nothing checked')
        return 0
    if node.result is None:
        node.get_logger().error('timed out before the drive ended')
        return 1
    return 0 if node.result else 1


def main(args=None) -> int:
    # (Stopped by Ctrl-C or SIGTERM, it exits 0, as a ROS 2 node does: a launch that is
    # stopped reports no failure.)
    return run_task(DriveCheck, 'drive_check', _check, (TeleopError,), args=args)


if __name__ == '__main__':
    sys.exit(main())
