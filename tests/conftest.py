"""Test session setup: DDS isolation for the whole session, and helpers for graph tests."""
from __future__ import annotations

import os
import random

# Isolate DDS before rclpy creates any context: a random domain, discovery on this host only.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('TEST_ROS_DOMAIN_ID') or str(random.randint(1, 100))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)
