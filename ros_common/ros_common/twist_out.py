"""A cmd_vel publisher of Twist or TwistStamped (stamped now, by the node's clock): what the
teleop node, the control panel and the coordinator send."""
from __future__ import annotations

from geometry_msgs.msg import Twist, TwistStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile


class TwistOut:

    def __init__(self, node: Node, topic: str, stamped: bool, depth: int = 10) -> None:
        self._node, self.stamped = node, stamped
        self.publisher = node.create_publisher(TwistStamped if stamped else Twist, topic,
                                               QoSProfile(depth=depth))

    def publish(self, vx: float, vy: float, wz: float) -> None:
        twist = Twist()
        twist.linear.x, twist.linear.y, twist.angular.z = float(vx), float(vy), float(wz)
        if self.stamped:
            msg = TwistStamped(twist=twist)
            msg.header.stamp = self._node.get_clock().now().to_msg()
            self.publisher.publish(msg)
        else:
            self.publisher.publish(twist)

    def destroy(self) -> None:
        self._node.destroy_publisher(self.publisher)
