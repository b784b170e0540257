"""Closed-loop cost: a pipeline trial's CPU per simulated second (all its nodes) with this
checkout against a baseline revision, side by side in one run (issue 63: the closed loop may
cost at most 5 % more than the open loop it replaced).

The baseline's Python packages are taken from git (``git archive``) into a scratch directory
and put first on the path of its trials' nodes; its own perturbed world is its world (this
checkout's has the conveyor's encoder). The two run one trial at a time, alternately, on the
same seeds and belt speed, so that both see the same machine. Prints the figures and writes
JSON to bench/results/.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Dict, List

from studies.trial_process import run_trial
from world_description.resources import resolve_resource

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
# The open loop's last revision: the commit before issue 63's first.
BASELINE = 'a1e249d'
WORLD = 'world_description/worlds/pipeline_cell_perturbed.yaml'
# The dense sweep's seeds (docs/trials/belt-speed-dense), at the speed its open loop handled worst.
SEEDS = (255808013, 2042992639, 1846837193, 1898632806, 1290703503, 903263730)
BELT = 0.14


def baseline_tree(rev: str, into: Path) -> Dict[str, str]:
    """The baseline's source tree under ``into``: the path its nodes import from (its Python
    packages, each ``<pkg>/<pkg>``), and its world."""
    into.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(['git', '-C', str(ROOT), 'archive', rev], check=True,
                             capture_output=True).stdout
    subprocess.run(['tar', '-x', '-C', str(into)], input=archive, check=True)
    packages = sorted(str(p.parent.parent) for p in into.glob('*/*/__init__.py')
                      if p.parent.name == p.parent.parent.name)
    return {'path': os.pathsep.join(packages), 'world': str(into / WORLD)}


def per_sim_second(results: List) -> Dict[str, float]:
    """CPU seconds per simulated second by node, over the trials together."""
    sim = sum(r.completion_time for r in results)
    nodes: Dict[str, float] = {}
    for r in results:
        for node, cpu in r.run.cpu_seconds.items():
            nodes[node] = nodes.get(node, 0.0) + cpu
    return {node: cpu / sim for node, cpu in nodes.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--baseline', default=BASELINE, help=f'git revision ({BASELINE})')
    parser.add_argument('--trials', type=int, default=4, help='trials of each (4)')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('BENCH_DOMAIN', 150)))
    args = parser.parse_args()
    seeds = [SEEDS[k % len(SEEDS)] for k in range(args.trials)]
    ours = str(resolve_resource(f'package://world_description/{WORLD.split("/", 1)[1]}'))
    runs: Dict[str, List] = {'baseline': [], 'this checkout': []}
    with tempfile.TemporaryDirectory() as tmp:
        base = baseline_tree(args.baseline, Path(tmp) / 'src')
        path = os.environ.get('PYTHONPATH', '')
        for k, seed in enumerate(seeds):
            for which in ('baseline', 'this checkout'):
                old = which == 'baseline'
                os.environ['PYTHONPATH'] = (base['path'] + os.pathsep + path) if old else path
                try:
                    result = run_trial(k, seed, BELT, args.domain,
                                       Path(tmp) / which.replace(' ', '_'),
                                       world=base['world'] if old else ours)
                finally:
                    os.environ['PYTHONPATH'] = path
                print(f'  {which}: seed {seed}: {result.status}, {result.completion_time:.1f} s '
                      f'simulated, handled {result.handled_verified}/{result.total}', flush=True)
                runs[which].append(result)
    figures: Dict[str, object] = {'baseline': args.baseline, 'seeds': seeds, 'belt_speed': BELT}
    for which, results in runs.items():
        nodes = per_sim_second(results)
        total = sum(nodes.values())
        each = [sum(r.run.cpu_seconds.values()) / r.completion_time for r in results]
        figures[which] = {'cpu_per_sim_second': total, 'by_node': nodes, 'per_trial': each,
                          'handled': sum(r.handled_verified for r in results),
                          'total': sum(r.total for r in results),
                          'statuses': [r.status for r in results]}
        print(f'{which}: {total:.3f} CPU-s per simulated second (trials: '
              f'{", ".join(f"{e:.3f}" for e in each)}; median {statistics.median(each):.3f}); '
              + ', '.join(f'{n} {v:.3f}' for n, v in sorted(nodes.items(), key=lambda i: -i[1])))
    ratio = (figures['this checkout']['cpu_per_sim_second']            # type: ignore[index]
             / figures['baseline']['cpu_per_sim_second'])              # type: ignore[index]
    figures['ratio'] = ratio
    print(f'this checkout / baseline: {ratio:.3f} (goal: at most 1.05)')
    (HERE / 'results').mkdir(exist_ok=True)
    (HERE / 'results' / 'bench_closed_loop.json').write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
