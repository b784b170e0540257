"""What the simulator node says about its inputs and its joints: each refused, clamped or
aborted command as a log line (at most one a second per robot, topic and kind, counting those
held back) and counted per input on /diagnostics once a second (wall time); each joint braked
back to its speed limit (joint_speed.py), latched on ``~/joint_limits`` since the start or the
last reset (a trial's result takes them); the mobile bases' closest approach, latched on
``~/base_clearance`` (base_clearance.py)."""
from __future__ import annotations

import time
from typing import Callable, List, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from ros_common.input_report import InputReport
from ros_common.log_limit import KeyedLimiter
from ros_common.stamps import stamp_from_ns
from sim_bridge.base_clearance import Closest
from sim_bridge.joint_speed import BrakeBook, Braked

# Latched, as robot_state_publisher and tf2's static broadcaster offer their topics.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class NodeDiagnostics:
    def __init__(self, node: Node, robots: Sequence[str], now_ns: Callable[[], int]) -> None:
        self._node, self._robots, self._now_ns = node, sorted(robots), now_ns
        self._rejections = KeyedLimiter(1.0)
        self._input_report = InputReport()
        self._brakes = BrakeBook()
        self._diagnostics_pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._brakes_pub = node.create_publisher(DiagnosticArray, '~/joint_limits', LATCHED)
        self._clearance_pub = node.create_publisher(DiagnosticArray, '~/base_clearance',
                                                    LATCHED)
        node.create_timer(1.0, self._publish_input_report,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

    def warn(self, key: tuple, kind: str, message: str) -> None:
        """A warning per ``key`` (robot, topic, kind, ...), at most one a second, counting those
        held; every one counted for /diagnostics under ``kind``."""
        self._input_report.add(key[0], key[1], kind, message)
        text = self._rejections.text(key, time.monotonic(), message)
        if text is not None:
            self._node.get_logger().warn(text)

    def trajectory_refused(self, robot: str, controller: str, kind: str, reason: str,
                           key: tuple, message: str) -> None:
        """A trajectory rejected or aborted (``kind``): an error per ``key``, at most one a
        second; every one counted for /diagnostics."""
        self._input_report.add(robot, f'{controller}/joint_trajectory', kind, reason)
        text = self._rejections.text(key, time.monotonic(), message)
        if text is not None:
            self._node.get_logger().error(text)

    def joints_braked(self, robot: str, time_ns: int, braked: Sequence[Braked]) -> None:
        lines = self._brakes.add(robot, time_ns * 1e-9, braked)
        for b, line in zip([b for b in braked if b.driven_past], lines):
            text = self._rejections.text((robot, b.joint, 'driven'), time.monotonic(), line)
            if text is not None:
                self._node.get_logger().warning(text)
        if lines:
            self.publish_brakes()

    def bases_closest(self, closest: Closest) -> None:
        """The bases' closest approach so far (by the ground truth), latched."""
        a, b = closest.robots
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK, name=f'{self._node.get_name()}: base clearance',
            message=f'{a} and {b} came within {closest.distance:.3f} m at {closest.time:.3f} s',
            values=[KeyValue(key='distance', value=f'{closest.distance:.4f}'),
                    KeyValue(key='time', value=f'{closest.time:.4f}'),
                    KeyValue(key='robots', value=f'{a},{b}')])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = stamp_from_ns(self._now_ns())
        self._clearance_pub.publish(msg)

    def clear_brakes(self) -> None:
        """The world was reset: no joint has been driven past its limit since."""
        self._brakes.clear()
        self.publish_brakes()

    def brake_statuses(self) -> List[DiagnosticStatus]:
        out = []
        for robot in self._robots:
            driven, message, values = self._brakes.status(robot)
            out.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN if driven else DiagnosticStatus.OK,
                name=f'{self._node.get_name()}: {robot} joint speed limits', hardware_id=robot,
                message=message, values=[KeyValue(key=k, value=v) for k, v in values]))
        return out

    def publish_brakes(self) -> None:
        msg = DiagnosticArray(status=self.brake_statuses())
        msg.header.stamp = stamp_from_ns(self._now_ns())
        self._brakes_pub.publish(msg)

    def _publish_input_report(self) -> None:
        msg = DiagnosticArray(status=self.brake_statuses())
        msg.header.stamp = stamp_from_ns(self._now_ns())
        for status in self._input_report.statuses():
            msg.status.append(DiagnosticStatus(
                level=bytes([status.level]), name=f'{self._node.get_name()}: {status.name}',
                hardware_id=status.hardware_id, message=status.message,
                values=[KeyValue(key=k, value=v) for k, v in status.values]))
        self._diagnostics_pub.publish(msg)
