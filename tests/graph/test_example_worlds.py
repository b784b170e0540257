"""Every example cell in world_description/worlds runs a trial through run_trials, as a user
runs it, and ends with every material resting on its destination by the simulator's ground
truth (docs/writing-a-cell.md)."""
import json
import re
import shutil
import subprocess
import time
from collections import Counter
from pathlib import Path

import pytest

from world_description.resources import resolve_resource
from world_description.world_config import load_world

WORLDS = sorted(p.name for p in Path(resolve_resource('package://world_description/worlds'))
                .glob('cell_*.yaml'))
# The belt speed a cell is run at, where not run_trials' draw (0.10-0.16 m/s): the Panda's cell
# at the speed issue 64 asks of it. (Faster, PyBullet's Panda drives its wrist's joint 5 past
# its speed limit as it follows a material: 4 of 8 delivered at 0.157 m/s; docs/known-limits.md.)
BELT_SPEEDS = {'cell_panda.yaml': 0.12}


def test_there_are_example_cells():
    assert {'cell_four_classes.yaml', 'cell_mixed_sizes.yaml', 'cell_two_trips.yaml',
            'cell_two_youbots.yaml', 'cell_laser_youbot.yaml', 'cell_panda.yaml'} <= set(WORLDS)


# The cells' trials run this many at a time, each campaign on DDS domains of its own from
# DOMAIN_BASE on (lock-step trials: a trial's result does not depend on the machine's load).
AT_ONCE = 2
DOMAIN_BASE = 200


def _start(name, out, log, lane):
    """A one-trial campaign of example cell ``name`` into ``out``, printing into ``log``."""
    speed = [f'{BELT_SPEEDS[name]}'] * 2 if name in BELT_SPEEDS else []
    with open(log, 'w') as sink:
        return subprocess.Popen(
            [shutil.which('run_trials'), '--world', f'package://world_description/worlds/{name}',
             '--trials', '1', '--seed0', '7', '--out', str(out), '--bar', 'off',
             '--domain-base', str(DOMAIN_BASE + 10 * lane),
             *(['--belt-speed', *speed] if speed else [])],
            stdout=sink, stderr=subprocess.STDOUT, text=True)


@pytest.fixture(scope='module')
def campaigns(tmp_path_factory):
    """Each example cell's one-trial campaign (run_trials, as a user runs it), AT_ONCE at a
    time: name -> (its output directory, its exit code, what it printed)."""
    root = tmp_path_factory.mktemp('examples')
    waiting, running, done = list(WORLDS), {}, {}
    try:
        while waiting or running:
            for lane in set(range(AT_ONCE)) - {v[1] for v in running.values()}:
                if waiting:
                    name = waiting.pop(0)
                    (root / name).mkdir()
                    log = root / name / 'run_trials.log'
                    running[name] = (_start(name, root / name / 'campaign', log, lane), lane)
            for name, (proc, _) in list(running.items()):
                if proc.poll() is not None:
                    done[name] = (root / name / 'campaign', proc.returncode,
                                  (root / name / 'run_trials.log').read_text())
                    del running[name]
            time.sleep(0.5)
    finally:
        for proc, _ in running.values():
            proc.kill()
            proc.wait()
    return done


@pytest.mark.parametrize('name', WORLDS)
def test_an_example_cell_completes_with_every_material_at_its_destination(name, campaigns):
    world = f'package://world_description/worlds/{name}'
    out, code, printed = campaigns[name]
    assert 'Traceback' not in printed
    result = json.loads((out / 'trial_000' / 'result.json').read_text())
    assert result['status'] == 'completed', (result['message'], result['not_at_destination'])
    assert code == 0, printed[-4000:]
    loaded = load_world(resolve_resource(world))
    materials = loaded.materials
    # Every material of every class, each where its class's rule puts it.
    assert Counter(m['color'] for m in result['final_materials']) == dict(materials.counts)
    assert all(m['at_destination'] for m in result['final_materials'])
    assert result['handled_verified'] == materials.total
    # Each material placed or delivered on a slot of its own (the pool's are its drops).
    slots = [e[5] for e in result['events'] if e[1] in ('placed', 'delivered')
             and 'slot' in e[5]]
    assert len(slots) == len(set(slots))
    roles = loaded.roles
    # The loader (any arm: the Panda's cell's is PyBullet's Franka Emika Panda) never driven
    # past a joint's speed limit.
    assert not [j for j in result['joints_driven_past'] if j['robot'] == roles.loader], \
        result['joints_driven_past']
    if len(roles.transports) > 1:
        # A fleet: every youBot carried, and no two bases ever came nearer than the cell's
        # clearance, by the simulator's ground truth at every physics step.
        assert {e[2] for e in result['events'] if e[1] == 'departing'} == set(roles.transports)
        closest = result['closest_bases']
        assert closest is not None and set(closest['robots']) <= set(roles.transports)
        assert closest['distance'] >= roles.clearance, closest
    else:
        assert 'closest_bases' not in result
    # A youBot with a laser scanner: its scans matched the walls, and every arrival says how
    # far its odometry was off there.
    lasers = {r.name for r in loaded.robots if r.laser is not None}
    arrivals = [e[5] for e in result['events'] if e[1] == 'arrived' and e[2] in lasers]
    assert bool(arrivals) == bool(lasers)
    assert all(re.search(r'laser: odometry off by .* [1-9][0-9]* scans matched', a)
               for a in arrivals), arrivals
    report = (out / 'report.md').read_text()
    assert f'Scenario: `{world}`: {materials.total} materials' in report
