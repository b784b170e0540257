"""Fixtures for graph tests: simulator processes and a probe node over real DDS."""
import pytest

from helpers import NodeProcess, Probe


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


@pytest.fixture
def start_node(tmp_path):
    procs = []

    def start(executable, *ros_args, name=None, **kwargs):
        proc = NodeProcess(executable, list(ros_args), tmp_path, name=name, **kwargs)
        procs.append(proc)
        return proc

    start.procs = procs          # (for a failing test's report: see NodeProcess.problems)
    yield start
    for proc in procs:
        proc.stop()
