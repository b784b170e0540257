"""A campaign's plan of trials: each trial's scenario seed and belt speed (drawn from the plan's
seed), a sweep's points with the same seeds at each, and the check that the plan's world (and
every point's) is one the pipeline can run, before any process starts."""
from __future__ import annotations

import random
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from studies.campaign import CampaignError
from studies.sweep import SweepError, grid, parse_axis, point_world
from studies.trial_process import PlanItem


def trial_plan(count: int, first: int, seed0: int, belt_range: Sequence[float]
               ) -> List[PlanItem]:
    rng = random.Random(seed0)
    plan: List[PlanItem] = []
    for k in range(first + count):
        seed = rng.randrange(1, 2 ** 31 - 1)
        speed = round(rng.uniform(*belt_range), 4)
        if k >= first:
            plan.append(PlanItem(trial=k, seed=seed, belt_speed=speed))
    return plan


def plan_of(opts: Dict[str, Any]) -> List[PlanItem]:
    if opts.get('sweep'):
        return sweep_plan(opts)
    lo, hi = opts['belt_speed']
    plan = trial_plan(opts['trials'], opts['first_trial'], opts['seed0'], (lo, hi))
    if opts['seeds'] is not None:
        plan = [{**item, 'trial': k, 'seed': seed} for k, (item, seed) in enumerate(
            zip(trial_plan(len(opts['seeds']), 0, opts['seed0'], (lo, hi)), opts['seeds']))]
    return plan


def sweep_plan(opts: Dict[str, Any]) -> List[PlanItem]:
    """Each point of the sweep with the same seeds (and, unless the sweep sets it, the same
    belt speeds): trial = point * trials per point + k."""
    per = opts['trials_per_point'] or opts['trials']
    points = grid([parse_axis(spec) for spec in opts['sweep']])
    base = trial_plan(per, 0, opts['seed0'], opts['belt_speed'])
    plan: List[PlanItem] = []
    for i, point in enumerate(points):
        for k, item in enumerate(base):
            plan.append(PlanItem(trial=i * per + k, seed=item['seed'],
                                 belt_speed=point.get('belt_speed', item['belt_speed']),
                                 parameters=dict(point)))
    return plan[opts['first_trial']:]


def check_sweep_worlds(opts: Dict[str, Any]) -> None:
    """Every point of a sweep gives a world the pipeline can run (CampaignError naming the
    first that does not), before any trial starts."""
    if not opts.get('sweep'):
        return
    with tempfile.TemporaryDirectory(prefix='run_trials-sweep-') as scratch:
        for i, point in enumerate(grid([parse_axis(spec) for spec in opts['sweep']])):
            try:
                world = point_world(opts['world'], point, Path(scratch) / str(i))
            except SweepError as exc:
                raise CampaignError(str(exc)) from None
            if world != opts['world']:
                check_world(world)


def check_world(world: str) -> None:
    """The cell's world file is one the pipeline can run (CampaignError otherwise): read here,
    once, before any process starts."""
    from cell_layout.layout import LayoutError
    from cell_layout.world_layout import layout_from_world
    from world_description.resources import ResourceError, resolve_resource
    from world_description.robot_files import check_robot_files
    from world_description.world_config import WorldConfigError, load_world
    path: Optional[Path] = None
    try:
        path = resolve_resource(world)
        config = load_world(path)
        layout_from_world(config)
        check_robot_files(config)          # (its robots' URDFs: the simulator's first read)
    except (WorldConfigError, LayoutError, ResourceError) as exc:
        text = ' '.join(str(exc).split())
        named = world in text or (path is not None and str(path) in text)
        raise CampaignError(f'--world: {text}' if named else f'--world {world}: {text}') \
            from None
