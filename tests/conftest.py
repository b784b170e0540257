"""Test session setup: DDS isolation for the whole session, and helpers for graph tests."""
from __future__ import annotations

import os
import random
import tempfile
from pathlib import Path

# Isolate DDS before rclpy creates any context: a domain of its own, discovery on this host only.
# DDS domains here: the suite 1-99 (and 100-159 for the runs of the determinism test), the demos
# 160-199, `run_trials` from 200 on; a suite, a demo and a campaign on one host never meet.
# Two suites on one host (two checkouts) do not either: each holds its domain with a lock file
# for the whole session, as run_trials' trials do (a random pick met another suite's nodes).
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / 'test-suite-domains'
_DOMAIN_LOCK = None


def _own_domain() -> str:
    global _DOMAIN_LOCK
    from ros_common.dds import hold_free_domain
    held = hold_free_domain(random.sample(range(1, 100), 99), DOMAIN_LOCKS)
    if held is None:
        raise RuntimeError('every DDS domain 1-99 is held by another test session on this host')
    domain, _DOMAIN_LOCK = held         # (held until the session's process ends)
    return str(domain)


os.environ['ROS_DOMAIN_ID'] = os.environ.get('TEST_ROS_DOMAIN_ID') or _own_domain()
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# A state machine's transition outside its table raises here, in the tests' own runs and in
# every coordinator they start (coordinator.pipeline.machine; elsewhere it is logged).
os.environ['ROBOT_SIM_STRICT_TRANSITIONS'] = '1'
os.environ.pop('ROS_STATIC_PEERS', None)


# Each test's tier by where it is (pytest.ini lists the markers).
_TIERS = {'unit': 'unit', 'graph': 'graph', 'test_demo.py': 'graph',
          'test_ament_layout.py': 'layout'}


def pytest_collection_modifyitems(config, items):
    import pytest
    here = Path(__file__).parent
    for item in items:
        first = Path(str(item.fspath)).relative_to(here).parts[0]
        tier = _TIERS.get(first)
        if tier is None:
            raise pytest.UsageError(f'{item.nodeid}: no tier for tests/{first} '
                                    '(tests/conftest.py _TIERS)')
        item.add_marker(tier)
        if tier != 'unit':
            item.add_marker('slow')


def pytest_terminal_summary(terminalreporter):
    """The counts some tests report (tests/helpers.py REPORT): the fuzz tests'."""
    import sys
    helpers = sys.modules.get('helpers')
    lines = getattr(helpers, 'REPORT', [])
    if lines:
        terminalreporter.section('reported by the tests')
        for line in lines:
            terminalreporter.write_line(line)
