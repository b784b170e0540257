"""run_trials --ray on a real Ray cluster of two nodes on this machine: the trials spread over
both nodes, every trial's files come back to the driver's directory, and the campaign's
figures equal those of the same seeds run locally (lock-step trials are deterministic).

The trials run a two-material cell (one purple, one orange: both of the Zu 12's routes and
the youBot's delivery) to keep the test short; the campaign machinery is the same."""
import csv
import json
import os
import random
import subprocess
from pathlib import Path

from ray.cluster_utils import Cluster

# Two trials: one on each node at once, and as many locally, two at once.
SEEDS = ('11', '12')
# Everything a trial's row holds except what depends on the machine's load.
COMPARED = ('trial', 'scenario_seed', 'belt_speed', 'status', 'completion_time',
            'identification_rate', 'grasp_success_rate', 'handling_success_rate', 'identified',
            'picked', 'delivered', 'grasp_attempts', 'grasp_successes', 'missed', 'failed')



def _campaign(out: Path, world: Path, domain_base: int, *extra: str) -> list:
    cmd = ['run_trials', '--seeds', *SEEDS, '--belt-speed', '0.10', '0.16', '--world',
           str(world), '--out', str(out), '--bar', 'off', '--domain-base', str(domain_base),
           '--progress-period', '30', *extra]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    with open(out / 'trials.csv') as f:
        return list(csv.DictReader(f))


def test_a_campaign_on_two_ray_nodes_matches_the_same_seeds_run_locally(tmp_path, small_world):
    base = random.Random().randrange(100, 150)
    cluster = Cluster(initialize_head=True, head_node_args={
        'num_cpus': 1, 'object_store_memory': 80 * 1024 ** 2, 'include_dashboard': False})
    try:
        cluster.add_node(num_cpus=1, object_store_memory=80 * 1024 ** 2)
        cluster.wait_for_nodes()
        on_ray = _campaign(tmp_path / 'ray', small_world, base, '--ray', cluster.address)
    finally:
        cluster.shutdown()
    local = _campaign(tmp_path / 'local', small_world, base, '--parallel', '2')

    assert [r['status'] for r in on_ray] == ['completed'] * len(SEEDS)
    assert [{k: r[k] for k in COMPARED} for r in on_ray] == \
        [{k: r[k] for k in COMPARED} for r in local]
    results = [json.loads((tmp_path / 'ray' / f'trial_{k:03d}' / 'result.json').read_text())
               for k in range(len(SEEDS))]
    assert len({r['run']['ray_node'] for r in results}) == 2, 'the trials did not use both nodes'
    # At the niceness of a process started here, not Ray's 15 for its workers (on a busy
    # machine a trial would crawl).
    assert {r['run']['niceness'] for r in results} == {os.nice(0)}
    for k in range(len(SEEDS)):
        trial_dir = tmp_path / 'ray' / f'trial_{k:03d}'
        for name in ('sim_node.log', 'coordinator_node.log', 'vision_node.log'):
            assert (trial_dir / name).stat().st_size > 0, f'{trial_dir / name} is empty'
    report = (tmp_path / 'ray' / 'report.md').read_text()
    local_report = (tmp_path / 'local' / 'report.md').read_text()
    assert _table_2(report) == _table_2(local_report)


def _table_2(report: str) -> list:
    """The report's rate and completion-time lines (not its wall times)."""
    return [line for line in report.splitlines()
            if line.startswith('|') and 'wall' not in line.lower()]
