"""What the youBot's laser scanner costs: a pipeline trial's CPU per simulated second (all its
nodes) in the example cell with a scanner (``cell_laser_youbot.yaml``) against the same cell
without it, side by side in one run, one trial at a time, alternately, on the same seeds: the
simulator's ray casting and scans, and the coordinator's matching of each scan to the walls
(goal: at most 5 % more). Prints the figures and writes JSON to bench/results/.
"""
import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Dict, List

import yaml

from studies.trial_process import run_trial
from world_description.resources import resolve_resource
from world_description.world_loading import world_data

HERE = Path(__file__).resolve().parent
WORLD = 'package://world_description/worlds/cell_laser_youbot.yaml'
SEEDS = (255808013, 2042992639, 1846837193, 1898632806)
BELT = 0.12
GOAL = 1.05


def per_sim_second(results: List) -> float:
    """CPU seconds per simulated second, all nodes, over the trials together."""
    return (sum(sum(r.run.cpu_seconds.values()) for r in results)
            / sum(r.completion_time for r in results))


def by_node(results: List) -> Dict[str, float]:
    """CPU seconds per simulated second of each node, over the trials together."""
    sim = sum(r.completion_time for r in results)
    nodes: Dict[str, float] = {}
    for r in results:
        for node, cpu in r.run.cpu_seconds.items():
            nodes[node] = nodes.get(node, 0.0) + cpu / sim
    return nodes


def worlds(into: Path) -> Dict[str, str]:
    """The cell as one file (its extends merged), with and without the scanner."""
    data = world_data(resolve_resource(WORLD))
    out = {}
    for which in ('laser', 'no laser'):
        if which == 'no laser':
            for robot in data['robots']:
                robot.pop('laser', None)
        path = into / f'{which.replace(" ", "_")}.yaml'
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        out[which] = str(path)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--trials', type=int, default=4, help='trials of each (4)')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('BENCH_DOMAIN', 150)))
    args = parser.parse_args()
    seeds = [SEEDS[k % len(SEEDS)] for k in range(args.trials)]
    runs: Dict[str, List] = {'no laser': [], 'laser': []}
    with tempfile.TemporaryDirectory() as tmp:
        files = worlds(Path(tmp))
        for k, seed in enumerate(seeds):
            for which in runs:
                result = run_trial(k, seed, BELT, args.domain,
                                   Path(tmp) / which.replace(' ', '_'), world=files[which])
                print(f'  {which}: seed {seed}: {result.status}, {result.completion_time:.1f} s '
                      f'simulated, handled {result.handled_verified}/{result.total}', flush=True)
                runs[which].append(result)
    figures: Dict[str, object] = {'world': WORLD, 'seeds': seeds, 'belt_speed': BELT}
    for which, results in runs.items():
        each = [sum(r.run.cpu_seconds.values()) / r.completion_time for r in results]
        figures[which] = {'cpu_per_sim_second': per_sim_second(results), 'per_trial': each,
                          'by_node': by_node(results),
                          'handled': sum(r.handled_verified for r in results),
                          'total': sum(r.total for r in results),
                          'statuses': [r.status for r in results]}
        print(f'{which}: {per_sim_second(results):.3f} CPU-s per simulated second (trials: '
              f'{", ".join(f"{e:.3f}" for e in each)}; median {statistics.median(each):.3f}); '
              f'handled {figures[which]["handled"]}/{figures[which]["total"]}; '  # type: ignore
              + ', '.join(f'{n} {v:.3f}' for n, v in sorted(by_node(results).items(),
                                                            key=lambda i: -i[1])))
    ratio = per_sim_second(runs['laser']) / per_sim_second(runs['no laser'])
    figures['ratio'] = ratio
    print(f'laser / no laser: {ratio:.3f} (goal: at most {GOAL})')
    (HERE / 'results').mkdir(exist_ok=True)
    (HERE / 'results' / 'bench_laser.json').write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
