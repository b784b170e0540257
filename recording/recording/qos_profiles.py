"""QoS for recording and replay: what a bag stores, and what to subscribe or publish with."""
from __future__ import annotations

from typing import List, Sequence, Tuple

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import parse_qos

# The rclpy enum values (rmw_qos_*_policy_t) of the policies that matter here.
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
_INFINITE = QosTime(0x7FFFFFFF, 0xFFFFFFFF)


def parse_offered_qos(text: str) -> List[Qos]:
    """Offered QoS profiles as a bag stores them (YAML text); empty text gives []."""
    if not text or not text.strip():
        return []
    try:
        return parse_qos(text)
    except Exception:
        return []


def bag_qos(reliability: int, durability: int, depth: int) -> Qos:
    """A rosbags Qos record from rclpy's policy values."""
    return Qos(QosHistory.KEEP_LAST, depth,
               QosReliability.RELIABLE if reliability == RELIABLE else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if durability == TRANSIENT_LOCAL
               else QosDurability.VOLATILE,
               _INFINITE, _INFINITE, QosLiveliness.AUTOMATIC, _INFINITE, False)


def adapt_to_publishers(policies: Sequence[Tuple[int, int]]) -> Tuple[int, int]:
    """(reliability, durability) for a subscription that matches every publisher.

    As rosbag2 does: reliable only if all publishers are reliable (a reliable reader does not
    match a best-effort writer), transient-local only if all of them are.
    """
    if not policies:
        return RELIABLE, VOLATILE
    reliability = RELIABLE if all(r == RELIABLE for r, _ in policies) else BEST_EFFORT
    durability = TRANSIENT_LOCAL if all(d == TRANSIENT_LOCAL for _, d in policies) else VOLATILE
    return reliability, durability


def replay_policies(offered: Sequence[Qos], msgtype: str) -> Tuple[int, int]:
    """(reliability, durability) to publish a recorded topic with.

    The recorded publishers' profiles when the bag has them (the first one), else the sensor
    profile for camera-like data and reliable for everything else.
    """
    if offered:
        q = offered[0]
        return (RELIABLE if q.reliability == QosReliability.RELIABLE else BEST_EFFORT,
                TRANSIENT_LOCAL if q.durability == QosDurability.TRANSIENT_LOCAL else VOLATILE)
    if msgtype in ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CameraInfo',
                   'sensor_msgs/msg/PointCloud2', 'sensor_msgs/msg/LaserScan'):
        return BEST_EFFORT, VOLATILE
    return RELIABLE, VOLATILE
