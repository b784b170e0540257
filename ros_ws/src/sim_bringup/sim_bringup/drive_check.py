"""Compare a base's odometry with the pose its received cmd_vel commands predict, then exit."""
from __future__ import annotations

import math
import sys
import time

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile

from controllers.cmd_guard import CommandGuard
from controllers.diff_drive import CommandIntegrator, Pose2D, wrap_angle
from sim_bridge.world import yaw_from_quaternion


def _float(description: str, lo: float, hi: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True,
                               floating_point_range=[FloatingPointRange(
                                   from_value=lo, to_value=hi, step=0.0)])


class DriveCheck(Node):
    """Listens to ``cmd_vel`` and ``odom``; done once commands ended and the base is at rest."""

    def __init__(self, **kwargs) -> None:
        super().__init__('drive_check', **kwargs)
        self.declare_parameter('max_speed', 0.2, _float('Limit the simulator clamps to', 1e-3,
                                                        10.0))
        self.declare_parameter('max_turn', 0.2, _float('Limit the simulator clamps to', 1e-3,
                                                       20.0))
        self.declare_parameter('cmd_vel_timeout', 0.5, _float('The simulator timeout [s]',
                                                              1e-3, 60.0))
        self.declare_parameter('position_tolerance', 0.05, _float('Pass limit [m]', 0.0, 10.0))
        self.declare_parameter('yaw_tolerance', 0.1, _float('Pass limit [rad]', 0.0, 3.2))
        self.declare_parameter('settle_time', 1.0, _float(
            'Done when no cmd_vel came for this long [s] and the base is at rest', 0.1, 60.0))
        self.declare_parameter('wall_timeout', 300.0, _float('Give up after [wall s]', 1.0,
                                                             3600.0))
        get = lambda name: self.get_parameter(name).value  # noqa: E731
        self.wall_timeout = get('wall_timeout')
        guard = CommandGuard((get('max_speed'), get('max_turn')), get('cmd_vel_timeout'))
        self._integrator = CommandIntegrator(guard)
        self._tol = (get('position_tolerance'), get('yaw_tolerance'))
        self._settle = get('settle_time')
        self._moving_commands = 0
        self._last_cmd_t = None
        self._odom = None
        self.result = None
        reliable = QoSProfile(depth=10)
        self.create_subscription(Twist, 'cmd_vel', self._on_cmd, reliable)
        self.create_subscription(Odometry, 'odom', self._on_odom, reliable)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_cmd(self, msg: Twist) -> None:
        t = self._now()
        self._integrator.command(msg.linear.x, msg.angular.z, t)
        self._last_cmd_t = t
        if msg.linear.x != 0.0 or msg.angular.z != 0.0:
            self._moving_commands += 1

    def _on_odom(self, msg: Odometry) -> None:
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self._integrator.advance_to(t)
        self._odom = msg
        at_rest = (abs(msg.twist.twist.linear.x) < 1e-3 and abs(msg.twist.twist.angular.z) < 1e-3)
        if (self.result is None and self._moving_commands and at_rest
                and t - self._last_cmd_t > self._settle):
            self.result = self._report()

    def _report(self) -> bool:
        p = self._odom.pose.pose
        actual = Pose2D(p.position.x, p.position.y, yaw_from_quaternion(
            (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)))
        predicted = self._integrator.pose
        dpos = math.hypot(actual.x - predicted.x, actual.y - predicted.y)
        dyaw = wrap_angle(actual.yaw - predicted.yaw)
        ok = dpos <= self._tol[0] and abs(dyaw) <= self._tol[1]
        log = self.get_logger().info if ok else self.get_logger().error
        log(f'final pose from odom:  x={actual.x:+.4f} m  y={actual.y:+.4f} m  '
            f'yaw={math.degrees(actual.yaw):+7.2f} deg')
        log(f'kinematics predicted:  x={predicted.x:+.4f} m  y={predicted.y:+.4f} m  '
            f'yaw={math.degrees(predicted.yaw):+7.2f} deg')
        log(f'error: position {dpos * 1000:.1f} mm (limit {self._tol[0] * 1000:.0f}), '
            f'yaw {math.degrees(dyaw):+.2f} deg (limit {math.degrees(self._tol[1]):.1f}) -> '
            + ('PASS' if ok else 'FAIL'))
        return ok


def main(args=None) -> int:
    rclpy.init(args=args)
    node = DriveCheck()
    deadline = time.monotonic() + node.wall_timeout
    code = 1
    try:
        while rclpy.ok() and node.result is None and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        if node.result is None:
            node.get_logger().error('timed out before the drive ended')
        else:
            code = 0 if node.result else 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
