"""Running a recorded trial again, as it was or with a change (``run_trials --rerun RUN --set
NAME=VALUE``): its result holds the seed, the belt speed, the physics step and the world file as
it was; the re-run takes them all, changes what ``--set`` names, and says what came out
different. Without a change, a lock-step trial runs again the same, to the last event."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import yaml

from ros_common.outputs import OutputError, make_dir, write_text
from studies.recorded import RecordError, load_trial
from studies.sweep import TRIAL_PARAMETERS, SweepError, point_world
from trial_record.result import TrialResult

ORIGINAL_WORLD = 'original_world.yaml'


class RerunError(ValueError):
    """A run that cannot be run again; the message is the line to print."""


@dataclass(frozen=True)
class Rerun:
    original: TrialResult
    source: Path                  # the original's result file
    world: str                    # the world file the re-run starts from (the original's)
    seed: int
    belt_speed: float
    time_step: float
    changes: Dict[str, float]     # --set: NAME: VALUE


def parse_sets(sets: Sequence[str]) -> Dict[str, float]:
    """``NAME=VALUE`` pairs: belt_speed, or a number of the world file by its path."""
    out: Dict[str, float] = {}
    for item in sets:
        name, sep, value = item.partition('=')
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise RerunError(f'--set {item!r}: give NAME=NUMBER (NAME: belt_speed or a number '
                             'of the world file, such as perturbations.camera.pixel_noise)')
        out[name.strip()] = number
    return out


def prepare(run: Path, sets: Sequence[str], out: Path) -> Rerun:
    """The re-run of ``run`` with ``sets``, its world written into ``out`` and checked."""
    try:
        original, source = load_trial(run)
    except RecordError as exc:
        raise RerunError(str(exc)) from None
    data = original.scenario.get('world_data')
    if not isinstance(data, dict) or original.scenario_seed is None:
        raise RerunError(f'{source}: the result does not keep the world it ran in (results '
                         'before the re-run feature); run it again with its seed instead: '
                         f'run_trials --seeds {original.scenario_seed}')
    changes = parse_sets(sets)
    try:
        make_dir(out, '--out')
    except OutputError as exc:
        raise RerunError(str(exc)) from None
    world = out / ORIGINAL_WORLD
    write_text(world, f'# The world of {source}, as it ran\n'
               + yaml.safe_dump(data, sort_keys=False))
    try:
        point_world(str(world), changes, out / '.check')
    except SweepError as exc:
        raise RerunError(str(exc).replace('the sweep point', '--set')) from None
    belt = changes.get('belt_speed', original.belt_speed)
    step = float(original.scenario.get('time_step', math.nan))
    if not (math.isfinite(belt) and 0.0 < belt <= 2.0 and math.isfinite(step) and step > 0.0):
        raise RerunError(f'{source}: belt speed {belt} or physics step {step} cannot be run')
    return Rerun(original, source, str(world), original.scenario_seed, belt, step, changes)


def world_changes(changes: Dict[str, float]) -> Dict[str, float]:
    return {k: v for k, v in changes.items() if k not in TRIAL_PARAMETERS}


FIGURES = (('status', 'status'), ('completion_time', 'completion time [s]'),
           ('identification_rate', 'identification'), ('grasp_success_rate', 'grasp'),
           ('handling_success_rate', 'handling'), ('delivered', 'delivered'),
           ('belt_stops', 'belt stops'), ('trips', 'trips'))


def figures(a: TrialResult, b: TrialResult) -> List[Tuple[str, str, str]]:
    """The Table-2 figures of two runs, side by side, as text."""
    def show(value: object) -> str:
        if isinstance(value, float):
            return f'{value:.3f}' if math.isfinite(value) else '-'
        return str(value)
    return [(label, show(getattr(a, key)), show(getattr(b, key))) for key, label in FIGURES]


def first_parting(a: TrialResult, b: TrialResult) -> str:
    """The first event where two runs part ('' if their events are the same)."""
    for k, (x, y) in enumerate(zip(a.events, b.events)):
        if x != y:
            return f'event {k}: {_event(x)} in the first run, {_event(y)} in the second run'
    if len(a.events) != len(b.events):
        shorter, longer, which = ((a, b, 'second') if len(a.events) < len(b.events)
                                  else (b, a, 'first'))
        return (f'event {len(shorter.events)}: the {which} run goes on with '
                f'{_event(longer.events[len(shorter.events)])}')
    return ''


def _event(e: Sequence[object]) -> str:
    time, kind, robot, material, color, detail = (list(e) + [''] * 6)[:6]
    who = f'{robot} ' if robot else ''
    what = f' {color} material {material}' if isinstance(material, int) and material >= 0 else ''
    return f'[{time} s] {who}{kind}{what}' + (f' ({detail})' if detail else '')
