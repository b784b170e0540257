"""Fixtures for graph tests: simulator processes, a probe node over real DDS, and a small
cell for tests that run whole trials."""
import pytest
import yaml

from helpers import NodeProcess, Probe
from world_description.resources import resolve_resource


@pytest.fixture
def small_world(tmp_path):
    """The paper's cell with two materials (one purple, one orange: both of the Zu 12's routes
    and the youBot's delivery), for tests of the trial machinery that need whole trials."""
    world = yaml.safe_load(resolve_resource(
        'package://world_description/worlds/pipeline_cell.yaml').read_text())
    world['materials']['counts'] = {'purple': 1, 'orange': 1}
    path = tmp_path / 'two_materials.yaml'
    path.write_text(yaml.safe_dump(world))
    return path


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
