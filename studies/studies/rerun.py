"""Running a recorded trial again, as it was or with a change (``run_trials --rerun RUN --set
NAME=VALUE``): its result holds the seed, the belt speed, the physics step and the world file as
it was; the re-run takes them all, changes what ``--set`` names, and says what came out
different. Without a change, a lock-step trial runs again the same, to the last event."""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import yaml

from ros_common.outputs import OutputError, make_dir, write_text
from studies.campaign import CampaignError
from studies.directory import ORIGINAL_WORLD
from studies.plan import check_world
from studies.recorded import RecordError, load_trial
from studies.sweep import TRIAL_PARAMETERS, SweepError, check_names, point_world
from trial_record.result import TrialResult


class RerunError(ValueError):
    """A run that cannot be run again; the message is the line to print."""


@dataclass(frozen=True)
class Rerun:
    original: TrialResult
    source: Path                  # the original's result file
    world: str                    # the world file the re-run starts from (the original's),
    #                               once written (Rerun.written_to); '' before
    seed: int
    belt_speed: float
    time_step: float
    changes: Dict[str, float]     # --set: NAME: VALUE

    def written_to(self, out: Path) -> 'Rerun':
        """The re-run with its world written into ``out`` (which must be there)."""
        world = out / ORIGINAL_WORLD
        write_text(world, f'# The world of {self.source}, as it ran\n'
                   + yaml.safe_dump(self.original.scenario['world_data'], sort_keys=False))
        return replace(self, world=str(world))


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
    try:
        check_names([item.partition('=')[0].strip() for item in sets], '--set')
    except SweepError as exc:
        raise RerunError(str(exc)) from None
    return out


def check(run: Path, sets: Sequence[str]) -> Rerun:
    """The re-run of ``run`` with ``sets``, every part of it checked (the changed world as
    ``--world`` checks a world) and nothing written yet (RerunError)."""
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
    belt = changes.get('belt_speed', original.belt_speed)
    step = float(original.scenario.get('time_step', math.nan))
    if not (math.isfinite(belt) and 0.0 < belt <= 2.0 and math.isfinite(step) and step > 0.0):
        raise RerunError(f'{source}: belt speed {belt} or physics step {step} cannot be run')
    rerun = Rerun(original, source, '', original.scenario_seed, belt, step, changes)
    with tempfile.TemporaryDirectory(prefix='run_trials-rerun-') as scratch:
        world = rerun.written_to(Path(scratch)).world
        changed = ''
        try:
            changed = point_world(world, changes, Path(scratch) / 'changed')
            check_world(changed)
        except SweepError as exc:
            raise RerunError(str(exc).replace('the sweep point', '--set')) from None
        except CampaignError as exc:
            # (Said of the world as --set changes it, not of a scratch file.)
            why = str(exc)
            for name in (f'--world {changed}: ', '--world: ', f'{changed}: ', changed):
                why = why.replace(name, '')
            raise RerunError(f'--set {", ".join(sets) or "(none)"}: the world as changed '
                             f'cannot be run: {why}') from None
    return rerun


def prepare(run: Path, sets: Sequence[str], out: Path) -> Rerun:
    """The re-run of ``run`` with ``sets``, checked (RerunError), its world written into
    ``out`` (made if need be) only then."""
    rerun = check(run, sets)
    try:
        make_dir(out, '--out')
    except OutputError as exc:
        raise RerunError(str(exc)) from None
    return rerun.written_to(out)


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
