"""Test session setup: DDS isolation for the whole session, and helpers for graph tests."""
from __future__ import annotations

import os
import random

# Isolate DDS before rclpy creates any context: a random domain, discovery on this host only.
# DDS domains here: the suite 1-99 (and 100-159 for the runs of the determinism test), the demos
# 160-199, `run_trials` from 200 on; a suite, a demo and a campaign on one host never meet.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('TEST_ROS_DOMAIN_ID') or str(random.randint(1, 99))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)


def pytest_terminal_summary(terminalreporter):
    """The counts some tests report (tests/helpers.py REPORT): the fuzz tests'."""
    import sys
    helpers = sys.modules.get('helpers')
    lines = getattr(helpers, 'REPORT', [])
    if lines:
        terminalreporter.section('reported by the tests')
        for line in lines:
            terminalreporter.write_line(line)
