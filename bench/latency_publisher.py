"""Publishes cmd_vel messages with unique speeds and prints their monotonic publish times."""
import json
import sys
import time

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node


def main() -> int:
    count = int(sys.argv[1])
    rclpy.init()
    node = Node('latency_publisher')
    pub = node.create_publisher(Twist, '/mini_robot/cmd_vel', 10)
    end = time.monotonic() + 30.0
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(0.5)
    published = []
    for i in range(count):
        msg = Twist()
        msg.linear.x = 0.05 + i * 1e-5  # unique, below max_speed, so applied unchanged
        published.append((msg.linear.x, time.monotonic()))
        pub.publish(msg)
        time.sleep(0.01)  # 100 Hz, faster than any teleop
    node.destroy_node()
    rclpy.try_shutdown()
    print(json.dumps(published))
    return 0


if __name__ == '__main__':
    sys.exit(main())
