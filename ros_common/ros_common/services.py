"""Quality of service of the project's service servers.

rclpy's default for services keeps the last 10 requests: 50 step requests sent at once by one
client got 17 replies, the other 33 never came. A server here keeps SERVICE_DEPTH requests
(and replies) per client, as a lock-step burst or a script calling in a loop needs. A client
that keeps fewer of its own requests (rclpy's default, 10) can still lose its oldest before
they are sent: give the client the same profile.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

SERVICE_DEPTH = 256
SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SERVICE_DEPTH,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
