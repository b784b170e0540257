"""Joint speed limits held in cells a user might write (issue 48): random cells, one lock-step
trial each, and each example world; the peak joint speed of every limited joint (arms, gripper
fingers, wheels) as the simulator's own joint states reported it, as a fraction of its URDF
limit, and the joints the simulator found driven past their limits (and braked back).

Random cells are drawn like the held-back ones of the 36-cell round (docs/writing-a-cell.md):
6 to 20 materials of up to four classes, 40 to 60 mm, 0.05 to 0.5 kg, belts 0.05 to 0.25 m/s.
The brake's cost, against a baseline in the same run: the paper's cell stepped in-process
(the arms following a motion, the belt carrying) with and without it.
Prints a table and writes JSON to bench/results/joint_limits.json.
"""
import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from controllers.joint_trajectory import TrajectoryPoint, TrajectoryRequest
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from studies.trial_process import run_trial
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world

HERE = Path(__file__).resolve().parent
WORLDS = resolve_resource(PIPELINE_CELL).parent
EXAMPLES = ('pipeline_cell', 'pipeline_cell_perturbed', 'cell_four_classes', 'cell_mixed_sizes',
            'cell_two_trips')
CLASSES = {
    'purple': {'color': [0.5, 0.15, 0.7, 1.0], 'destination': 'ground_target', 'route': 'place'},
    'orange': {'color': [1.0, 0.5, 0.05, 1.0], 'destination': 'pool_floor', 'route': 'carry'},
    'blue': {'color': [0.1, 0.3, 0.9, 1.0], 'destination': 'pool_platform', 'route': 'carry'},
    'green': {'color': [0.1, 0.8, 0.2, 1.0], 'destination': 'green_target', 'route': 'place'},
}
GREEN_TARGET = {'name': 'green_target', 'shape': 'box', 'size': [0.2, 0.2, 0.002],
                'position': [-0.55, -0.15, 0.001], 'color': [0.7, 0.85, 0.7, 1.0],
                'collision': False}


def random_cell(rng: np.random.Generator, out: Path, k: int):
    """A cell of 6-20 materials of 1-4 classes (orange, carried, always)."""
    others = [str(n) for n in rng.permutation(['purple', 'blue', 'green'])]
    names = ['orange'] + others[:rng.integers(0, 4)]
    total = int(rng.integers(6, 21))
    # The others 1-3 each (the pool's platform has 4 drop spots in reach), orange the rest.
    counts = [total - 0] + [int(rng.integers(1, 4)) for _ in names[1:]]
    counts[0] = total - sum(counts[1:])
    classes = {n: {**CLASSES[n], 'count': int(c), 'size': round(float(rng.uniform(0.04, 0.06)), 3),
                   'mass': round(float(rng.uniform(0.05, 0.5)), 3)}
               for n, c in zip(names, counts)}
    belt = round(float(rng.uniform(0.05, 0.25)), 3)
    world = {'extends': str(WORLDS / 'pipeline_cell.yaml'), 'conveyor': {'belt_speed': belt},
             'materials': {'classes': classes}}
    if 'green' in names:
        world['more_obstacles'] = [GREEN_TARGET]
    path = out / f'cell_{k:02d}.yaml'
    path.write_text(yaml.safe_dump(world, sort_keys=False))
    return path, belt


class _Count(NullSink):
    def __init__(self):
        self.brakings = 0

    def on_joints_braked(self, robot, time_ns, braked):
        self.brakings += len(braked)


def brake_cost(steps=2400, rounds=3):
    """CPU seconds per simulated second of the paper's cell, with the brake and without it
    (its limiter switched off), the two interleaved over ``rounds``; the braking count."""
    timings = {True: [], False: []}
    brakings = 0
    for _ in range(rounds):
        for on in (True, False):
            world = SimWorld(load_world(resolve_resource(PIPELINE_CELL)))
            runner = SimRunner(world, DriveLimits(), 50.0)
            if not on:
                for robot in world.robots.values():
                    robot.speed_limiter.enforce = lambda: []
            zu12 = ['joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_6']
            runner.set_trajectory('zu12', 'arm_controller', TrajectoryRequest(tuple(zu12), (
                TrajectoryPoint(3.0, (1.0, 0.5, -0.5, 0.3, 0.5, 0.5)),
                TrajectoryPoint(6.0, (-1.0, 0.2, 0.3, -0.3, -0.5, 0.0)))))

            sink = _Count()
            start = time.process_time()
            runner.advance(steps, sink)
            timings[on].append(time.process_time() - start)
            brakings += sink.brakings
            world.close()
    sim_s = steps / 240.0
    with_brake = min(timings[True]) / sim_s
    without = min(timings[False]) / sim_s
    return {'cpu_per_sim_s_with_brake': with_brake, 'cpu_per_sim_s_without': without,
            'ratio': with_brake / without, 'brakings': brakings}


def summary(name, result):
    peaks = result.peak_joint_speed
    worst = max(peaks.items(), key=lambda kv: kv[1].get('fraction_of_limit', 0.0),
                default=('', {}))
    return {'cell': name, 'status': result.status, 'completion_time': result.completion_time,
            'handled': f'{result.handled_verified}/{result.total}',
            'peak_fraction': worst[1].get('fraction_of_limit', 0.0),
            'peak_joint': f'{worst[0]} {worst[1].get("joint", "")}',
            'peaks': peaks, 'driven_past': result.joints_driven_past,
            'message': result.message[:300]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--cells', type=int, default=36)
    ap.add_argument('--seed', type=int, default=48)
    ap.add_argument('--examples', action='store_true', help='run each example world too')
    ap.add_argument('--parallel', type=int, default=2)
    ap.add_argument('--out', default=str(HERE / 'results' / 'joint_limits.json'))
    args = ap.parse_args(argv)
    cost = brake_cost()
    print(f'brake cost: {cost["cpu_per_sim_s_with_brake"]:.3f} CPU-s per simulated s with it, '
          f'{cost["cpu_per_sim_s_without"]:.3f} without (ratio {cost["ratio"]:.3f}; '
          f'{cost["brakings"]} brakings)', flush=True)
    rng = np.random.default_rng(args.seed)
    work = Path(tempfile.mkdtemp(prefix='joint_limits_'))
    jobs = [(f'random {k:02d}', *random_cell(rng, work, k)) for k in range(args.cells)]
    if args.examples:
        jobs += [(name, WORLDS / f'{name}.yaml', 0.12) for name in EXAMPLES]

    def run(item):
        k, (name, world, belt) = item
        result = run_trial(k, args.seed + k, belt, 200 + k % 16, work / 'runs',
                           world=str(world))
        row = summary(name, result)
        print(f'{name:24s} {row["status"]:10s} {row["completion_time"]:6.1f} s '
              f'{row["handled"]:>6s}  peak {row["peak_fraction"]:.4f} ({row["peak_joint"]})  '
              f'driven past: {len(row["driven_past"])}', flush=True)
        return row

    with ThreadPoolExecutor(args.parallel) as pool:
        rows = list(pool.map(run, enumerate(jobs)))
    worst = max(r['peak_fraction'] for r in rows)
    done = sum(r['status'] == 'completed' for r in rows)
    driven = [d for r in rows for d in r['driven_past']]
    print(f'{done}/{len(rows)} completed; worst peak {worst:.4f} of a limit; '
          f'{len(driven)} joints driven past their limits (braked back)')
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({'rows': rows, 'worst_peak': worst, 'brake_cost': cost,
                                          'completed': done, 'cells': len(rows)}, indent=1))
    return 0 if worst <= 1.0 + 1e-9 else 1


if __name__ == '__main__':
    sys.exit(main())
