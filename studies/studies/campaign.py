"""A campaign's state on disk, checked before it is used: its plan (``campaign.json``), its
trials' results (``trial_NNN/result.json``), the lock that keeps a second runner out of its
directory, and its CSV and report rebuilt from what is there.

Every file here may have been left by a crash, edited by hand or written by another version:
each is read into the types the runner needs, or refused with one line that names the file
and what is wrong with it (``CampaignError``).
"""
from __future__ import annotations

import csv
import fcntl
import io
import json
import math
import os
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from ros_common.outputs import OutputError, open_lock, write_text
from studies.directory import CAMPAIGN_FILE
from studies.sweep import SweepError, grid, parse_axis, point_world
from studies.trial_graph import CONTROL_RATE, TIME_STEP
from studies.trial_process import PlanItem, scenario
from trial_record.records import Fields, RecordError, is_int, is_number, parse_json, read_text
from trial_record.result import CSV_FIELDS, RESULT_FILE, TrialResult, read_result
from world_description import PIPELINE_CELL

LOCK_FILE = '.run_trials.lock'
# The options that define a campaign's plan, and their defaults. A campaign keeps them in
# its directory (CAMPAIGN_FILE), so that ``--resume DIR`` needs nothing else.
PLAN_DEFAULTS: Dict[str, Any] = {
    'trials': 10, 'seed0': 2026, 'seeds': None, 'first_trial': 0,
    'belt_speed': [0.10, 0.16], 'world': PIPELINE_CELL, 'time_step': TIME_STEP,
    # A sweep (studies.sweep): one or two NAME=VALUES, `trials_per_point` trials at each
    # point (else `trials`); the report names the first point where a rate is below
    # `break_below`.
    'sweep': None, 'trials_per_point': None, 'break_below': 0.9}
MAX_TRIALS = 100_000
MAX_SEED = 2 ** 31 - 1              # (the simulator's scenario_seed is a 32-bit integer)
MAX_BELT_SPEED = 0.5                # m/s
MAX_CAMPAIGN_BYTES = 16 * 1024 * 1024   # a plan of 100,000 seeds is about 1.2 MB


class CampaignError(ValueError):
    """A campaign's file or option that cannot be used; the message is the one line to print."""


def check_plan(plan: Any, source: str) -> Dict[str, Any]:
    """A plan's options (all of them, or some over the defaults) as the runner takes them;
    raises CampaignError naming ``source`` and the first option that is wrong."""
    if not isinstance(plan, dict):
        raise CampaignError(f'{source}: the plan must be a mapping of options, got '
                            f'{type(plan).__name__}')
    unknown = sorted(set(plan) - set(PLAN_DEFAULTS))
    if unknown:
        raise CampaignError(f'{source}: unknown plan options {unknown}')

    def bad(key: str, what: str) -> CampaignError:
        return CampaignError(f'{source}: {key} must be {what}, got {plan[key]!r:.60}')
    if 'trials' in plan and not (is_int(plan['trials']) and 1 <= plan['trials'] <= MAX_TRIALS):
        raise bad('trials', f'an integer within 1..{MAX_TRIALS}')
    if 'seed0' in plan and not is_int(plan['seed0']):
        raise bad('seed0', 'an integer')
    if 'first_trial' in plan and not (is_int(plan['first_trial']) and plan['first_trial'] >= 0):
        raise bad('first_trial', 'an integer >= 0')
    seeds = plan.get('seeds')
    if seeds is not None and not (isinstance(seeds, list) and 1 <= len(seeds) <= MAX_TRIALS
                                  and all(is_int(s) and 0 <= s <= MAX_SEED for s in seeds)):
        raise bad('seeds', f'a list of integers within 0..{MAX_SEED}')
    if 'belt_speed' in plan:
        speeds = plan['belt_speed']
        if not (isinstance(speeds, (list, tuple)) and len(speeds) == 2
                and all(is_number(v) and math.isfinite(v) for v in speeds)
                and 0.0 < speeds[0] <= speeds[1] <= MAX_BELT_SPEED):
            raise bad('belt_speed', f'[LO, HI] with 0 < LO <= HI <= {MAX_BELT_SPEED} m/s')
    if 'world' in plan and not (isinstance(plan['world'], str) and plan['world'].strip()):
        raise bad('world', 'the path or package:// address of a world file')
    if 'time_step' in plan and not (is_number(plan['time_step'])
                                    and 1e-4 <= plan['time_step'] <= 1.0 / CONTROL_RATE):
        raise bad('time_step', f'within [0.0001, {1.0 / CONTROL_RATE:.4f}] s (a physics step '
                  'at least once per control tick)')
    _check_sweep(plan, bad)
    checked = dict(plan)
    if 'belt_speed' in checked:
        checked['belt_speed'] = [float(v) for v in checked['belt_speed']]
    return checked


def _check_sweep(plan: Dict[str, Any], bad: Callable[[str, str], CampaignError]) -> None:
    """The sweep's options of a plan (check_plan)."""
    sweep = plan.get('sweep')
    if sweep is not None:
        if not (isinstance(sweep, list) and 1 <= len(sweep) <= 2
                and all(isinstance(spec, str) for spec in sweep)):
            raise bad('sweep', 'one or two NAME=VALUES')
        try:
            axes = [parse_axis(spec) for spec in sweep]
            points = grid(axes)
        except SweepError as exc:
            raise CampaignError(str(exc)) from None
        if any(not 0.0 < p['belt_speed'] <= MAX_BELT_SPEED for p in points if 'belt_speed' in p):
            raise bad('sweep', f'belt speeds within (0, {MAX_BELT_SPEED}] m/s')
        if 'seeds' in plan and plan['seeds'] is not None:
            raise CampaignError('--sweep runs the same seeds at every point: give '
                                '--trials-per-point, not --seeds')
    per = plan.get('trials_per_point')
    if per is not None and not (is_int(per) and 1 <= per <= MAX_TRIALS):
        raise bad('trials_per_point', f'an integer within 1..{MAX_TRIALS}')
    if sweep is not None:
        trials = len(points) * (per or plan.get('trials', PLAN_DEFAULTS['trials']))
        if trials > MAX_TRIALS:
            raise CampaignError(f'the sweep plans {trials} trials ({len(points)} points): at '
                                f'most {MAX_TRIALS}')
    below = plan.get('break_below')
    if below is not None and not (is_number(below) and 0.0 < below <= 1.0):
        raise bad('break_below', 'a rate within (0, 1]')


def read_campaign(out: Path) -> Optional[Dict[str, Any]]:
    """The plan stored in a campaign directory, or None if it has no campaign file."""
    path = out / CAMPAIGN_FILE
    if not path.exists() and not path.is_symlink():
        return None
    try:
        f = Fields(parse_json(read_text(path, 'a campaign file', MAX_CAMPAIGN_BYTES),
                              str(path)), str(path))
        f.only(('plan', 'code'))
        f.text('code', '', limit=200)
        if not f.has('plan'):
            raise RecordError(f'{path} is not a campaign file (no "plan")')
    except RecordError as exc:
        raise CampaignError(str(exc)) from None
    return check_plan(f.data['plan'], str(path))


def write_campaign(out: Path, plan: Dict[str, Any], code: str) -> None:
    """The plan, written whole or not at all (a crash leaves the previous file)."""
    write_text(out / CAMPAIGN_FILE, json.dumps({'plan': plan, 'code': code}, indent=1))


def trial_results(out: Path) -> Tuple[List[TrialResult], List[str]]:
    """Every usable result in a campaign directory (with its trial number), and a line for
    each one that is not."""
    results, problems = [], []
    for path in sorted(out.glob(f'trial_*/{RESULT_FILE}')):
        result, problem = read_result(path)
        if problem is not None:
            problems.append(f'{path}: {problem}')
            continue
        if result is None:
            continue
        if result.trial is None:
            try:
                result = result.with_run(trial=int(path.parent.name.split('_')[1]))
            except (IndexError, ValueError):
                problems.append(f'{path}: not in a trial_NNN directory')
                continue
        results.append(result)
    return results, problems


@contextmanager
def campaign_lock(out: Path) -> Iterator[None]:
    """Hold the campaign directory for this runner (an advisory lock, gone with its process):
    a second runner into it is refused with the first one's process id."""
    try:
        handle: IO[str] = open_lock(out / LOCK_FILE, 'the campaign lock')
    except OutputError as exc:
        raise CampaignError(str(exc)) from None
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or 'another process'
            raise CampaignError(f'{out} is in use by another run_trials ({holder}); wait for '
                                'it to end, or give another --out') from None
        handle.seek(0)
        handle.truncate()
        handle.write(f'pid {os.getpid()}\n')
        handle.flush()
        yield
    finally:
        handle.close()


def write_csv(trials: Sequence[TrialResult], path: Path) -> None:
    """The trials' rows, written whole or not at all (a signal mid-write leaves the last)."""
    text = io.StringIO(newline='')
    writer = csv.DictWriter(text, CSV_FIELDS)
    writer.writeheader()
    for t in sorted(trials, key=lambda t: t.trial or 0):
        writer.writerow(t.to_row())
    write_text(path, text.getvalue())


def rebuild(out: Path) -> int:
    results, problems = trial_results(out)
    if problems:
        for line in problems:
            print(f'run_trials: error: {line}; remove it, or run_trials --resume {out} runs '
                  'that trial again', file=sys.stderr)
        return 2
    if not results:
        print(f'[trials] no trial_*/result.json in {out}', file=sys.stderr)
        return 1
    write_csv(results, out / 'trials.csv')
    from studies.report import write_report
    speeds = [r.belt_speed for r in results if math.isfinite(r.belt_speed)]
    note = (f'{len(results)} trials (lock-step), rebuilt from their results; belt speeds '
            f'{min(speeds):.3f}-{max(speeds):.3f} m/s; seeds and wall times in trials.csv.'
            if speeds else f'{len(results)} trials, rebuilt from their results.')
    try:
        plan = (read_campaign(out) or {}).get('plan', {})
    except CampaignError:
        plan = {}
    world = plan.get('world') if isinstance(plan, dict) else None
    report = write_report(results, out, {'note': note, **({'world': world} if world else {}),
                                         'break_below': plan.get('break_below')})
    print(f'[trials] {len(results)} trials: CSV {out / "trials.csv"}, report {report}')
    return 0


class Reuse:
    """Which results already in a directory a plan's trials may take instead of running: only
    a trial that ran the cell to an outcome (``TrialResult.ran``), and ran what the plan's
    trial would run: the same seed, belt speed and sweep point, the same world as one mapping
    (its file as it is now, what it extends merged in, the point's values set), the same
    physics step, and the same code (``code_version``)."""

    def __init__(self, world: str, time_step: float, code: str) -> None:
        self.world, self.time_step, self.code = world, time_step, code
        self._worlds: Dict[str, Any] = {}

    def _world_of(self, parameters: Dict[str, float]) -> Any:
        """The world a trial at ``parameters`` runs, as its result keeps it (trial_process.
        scenario), or the reason it cannot be read now."""
        key = json.dumps(parameters, sort_keys=True)
        if key not in self._worlds:
            with tempfile.TemporaryDirectory(prefix='run_trials-reuse-') as scratch:
                try:
                    ran = scenario(point_world(self.world, parameters, Path(scratch)),
                                   self.time_step)
                except SweepError as exc:
                    ran = {'world_problem': str(exc)}
            self._worlds[key] = (json.loads(json.dumps(ran['world_data'])) if 'world_data'
                                 in ran else None)
        return self._worlds[key]

    def why_not(self, r: TrialResult, item: PlanItem) -> str:
        """'' if ``r`` may stand for the plan's ``item``; else why not, in words."""
        if not r.ran:
            return f'did not run ({r.status})'
        if (r.scenario_seed != item['seed'] or r.belt_speed != item['belt_speed']
                or r.parameters != item.get('parameters', {})):
            return 'is of another seed, belt speed or setting'
        if r.run.code != self.code:
            return f'was made by other code ({r.run.code}; this is {self.code})'
        if r.scenario.get('time_step') != self.time_step:
            ran = r.scenario.get('time_step', 'unknown')
            return f'is of another physics step ({ran} s; this is {self.time_step:g} s)'
        world = self._world_of(dict(item.get('parameters', {})))
        if world is None or r.scenario.get('world_data') != world:
            return 'is of another world (the world file has changed since)'
        return ''


def finished_result(out: Path, item: PlanItem, reuse: Reuse) -> Optional[TrialResult]:
    """The result of a planned trial already in ``out`` that ``reuse`` allows, if any; a
    result that cannot be used is said so, and the trial runs again."""
    path = out / f'trial_{item["trial"]:03d}' / RESULT_FILE
    r, problem = read_result(path)
    if problem is not None:
        print(f'[trials] {path}: {problem}; trial {item["trial"]} runs again', flush=True)
    if r is None:
        return None
    why = reuse.why_not(r, item)
    if why:
        print(f'[trials] trial {item["trial"]} runs again: its result ({path.parent.name}) '
              f'{why}', flush=True)
        return None
    return r if r.trial is not None else r.with_run(trial=item['trial'])
