"""Send one joint trajectory to an arm controller and report where the arm ended up.

    arm_move --ros-args -r __ns:=/youbot -p positions:=[0.5,0.6,0.9,0.8,0.0] -p duration:=2.0

Publishes on ``<controller>/joint_trajectory`` once the simulator listens, follows
``<controller>/controller_state`` until the motion ends, and exits 0 when every joint is within
``tolerance`` of its target (1 when not, or when the simulator rejected the trajectory).
"""
from __future__ import annotations

import sys
import time
from typing import Optional

import rclpy
from control_msgs.msg import JointTrajectoryControllerState
from rclpy.node import Node
from rclpy.qos import QoSProfile
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from controllers.youbot_arm import JOINT_NAMES
from ros_common.node_main import run_task
from ros_common.params import Param, declare_params
from ros_common.stamps import set_stamp

PARAMS = (
    Param('controller', 'arm_controller', 'Controller name: topics <controller>/joint_trajectory '
          'and <controller>/controller_state'),
    Param('joint_names', list(JOINT_NAMES), 'Joints of the trajectory'),
    Param('positions', [0.0] * len(JOINT_NAMES), 'Target positions, one per joint [rad or m]'),
    Param('duration', 2.0, 'Time to reach the target [s]', 0.01, 600.0),
    Param('tolerance', 0.01, 'Largest accepted final error per joint [rad or m]', 1e-6, 1.0),
)


class ArmMove(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('arm_move', **kwargs)
        p = declare_params(self, PARAMS)
        names, positions = list(p['joint_names']), [float(v) for v in p['positions']]
        if len(names) != len(positions):
            raise ValueError(f'{len(positions)} positions for {len(names)} joints')
        self.names, self.target, self.tolerance = names, positions, p['tolerance']
        point = JointTrajectoryPoint(positions=positions)
        ns = round(p['duration'] * 1e9)
        set_stamp(point.time_from_start, ns)
        self.trajectory = JointTrajectory(joint_names=names, points=[point])
        controller = p['controller']
        self.pub = self.create_publisher(JointTrajectory, f'{controller}/joint_trajectory',
                                         QoSProfile(depth=10))
        self.create_subscription(JointTrajectoryControllerState,
                                 f'{controller}/controller_state', self._on_state,
                                 QoSProfile(depth=10))
        self.sent_at: Optional[float] = None     # (time.monotonic())
        self.started = False
        self.result: Optional[int] = None

    def _on_state(self, msg: JointTrajectoryControllerState) -> None:
        if self.sent_at is None or self.result is not None:
            return
        # (Following a trajectory, the reference moves; holding, its velocity is exactly 0.)
        moving = any(v != 0.0 for v in msg.reference.velocities)
        self.started |= moving
        if not (self.started and not moving):
            return
        index = {n: i for i, n in enumerate(msg.joint_names)}
        errors = {n: abs(msg.feedback.positions[index[n]] - t)
                  for n, t in zip(self.names, self.target)}
        worst = max(errors, key=lambda n: errors[n])
        text = ', '.join(f'{n} {e:.4f}' for n, e in errors.items())
        if errors[worst] <= self.tolerance:
            self.get_logger().info(f'reached the target: errors {text}')
            self.result = 0
        else:
            self.get_logger().error(f'target missed: errors {text} (tolerance '
                                    f'{self.tolerance})')
            self.result = 1


def _move(node: 'ArmMove') -> int:
    end = time.monotonic() + 30.0
    while rclpy.ok() and node.pub.get_subscription_count() == 0:
        if time.monotonic() > end:
            node.get_logger().error(f'nobody listens on {node.pub.topic_name}')
            return 1
        rclpy.spin_once(node, timeout_sec=0.05)
    node.pub.publish(node.trajectory)
    node.sent_at = sent = time.monotonic()
    node.get_logger().info(f'sent {node.names} -> {node.target}')
    while rclpy.ok() and node.result is None:
        rclpy.spin_once(node, timeout_sec=0.1)
        if not node.started and time.monotonic() - sent > 5.0:
            node.get_logger().error('the controller did not start the trajectory (rejected?'
                                    ' see the simulator log)')
            return 1
    if node.result is None:           # (stopped by Ctrl-C or SIGTERM: not a failure)
        node.get_logger().info('stopped before the motion ended')
        return 0
    return node.result


def main(args=None) -> int:
    return run_task(ArmMove, 'arm_move', _move, (ValueError,), args=args)   # (Ctrl-C: 0)


if __name__ == '__main__':
    sys.exit(main())
