"""A recorded trial, from its result or from its bag alone.

A trial's bag keeps what ran in its metadata (``custom_data``, in metadata.yaml and in the MCAP
file's rosbag2 record): ``robot_sim.trial``, JSON with the trial's number, seed, belt speed,
sweep parameters, code version and scenario (the world as it was, the physics step). The
coordinator's last ``/coordinator_node/state`` in it carries the run's result. So a bag copied
away from its trial's directory can still be re-run (``run_trials --rerun BAG``), compared
(``compare_runs``) and drawn (``storyboard``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

import yaml

from recording.analysis import AnalysisError, open_reader, read_messages
from trial_record.records import Fields, RecordError, parse_json, read_text
from trial_record.result import (
    MAX_BELT_SPEED,
    MAX_SEED,
    MAX_TRIAL,
    RESULT_FILE,
    TrialResult,
    check_parameters,
    check_scenario,
    read_result,
)

TRIAL_KEY = 'robot_sim.trial'
STATE_TOPIC = '/coordinator_node/state'
MAX_METADATA_BYTES = 16 * 1024 * 1024      # a trial's metadata.yaml: about 30 kB

__all__ = ['RecordError', 'TrialRecord', 'bag_metadata', 'is_bag', 'trial_bag', 'find_result',
           'load_trial', 'custom_data', 'result_from_bag']


@dataclass(frozen=True)
class TrialRecord:
    """What ran, as a trial's bag keeps it (``TRIAL_KEY``), checked field by field: a bag
    copied from elsewhere and edited is data, not instructions (its trial number names
    directories, its world is run again)."""
    trial: Optional[int]
    scenario_seed: Optional[int]
    belt_speed: float
    code: str
    parameters: Dict[str, float] = field(default_factory=dict)
    scenario: Dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_json(cls, text: str, what: str) -> 'TrialRecord':
        f = Fields(parse_json(text, what), what)
        f.only(('trial', 'scenario_seed', 'belt_speed', 'code', 'parameters', 'scenario'))
        return cls(trial=f.integer('trial', 0, MAX_TRIAL, None, none=True),
                   scenario_seed=f.integer('scenario_seed', -1, MAX_SEED, None, none=True),
                   belt_speed=f.number('belt_speed', 0.0, MAX_BELT_SPEED, math.nan, nan=True),
                   code=f.text('code', '', limit=200),
                   parameters=check_parameters(f), scenario=check_scenario(f))


def bag_metadata(trial: int, seed: int, belt_speed: float, code: str,
                 scenario: Dict[str, Any],
                 parameters: Optional[Dict[str, float]] = None) -> Dict[str, str]:
    """The custom data a trial's bag keeps (``TRIAL_KEY``: what ran, as JSON; the world's keys
    in their order, which is part of it: the materials' classes are planned in it)."""
    return {TRIAL_KEY: json.dumps({
        'trial': trial, 'scenario_seed': seed, 'belt_speed': belt_speed, 'code': code,
        'parameters': dict(parameters or {}), 'scenario': scenario})}


def is_bag(path: Path) -> bool:
    """Whether ``path`` is a rosbag2 bag (a directory with metadata.yaml)."""
    return path.is_dir() and (path / 'metadata.yaml').is_file()


def trial_bag(trial_dir: Path) -> Optional[Path]:
    """The bag in a trial's directory, if it was recorded."""
    found = sorted(p.parent for p in trial_dir.glob('*/metadata.yaml'))
    return found[0] if found else None


def find_result(run: Path) -> Path:
    """The result file of a run: ``run`` itself, its trial directory, or a campaign directory
    with exactly one trial (what ``make demo`` leaves)."""
    if run.is_file():
        return run
    if (run / RESULT_FILE).is_file():
        return run / RESULT_FILE
    found = sorted(run.glob(f'trial_*/{RESULT_FILE}'))
    if len(found) == 1:
        return found[0]
    if not found:
        raise RecordError(f'{run}: no trial result there (a result.json, a trial directory, a '
                          'run directory with one trial, or a trial\'s bag)')
    raise RecordError(f'{run} holds {len(found)} trials: name one (its trial_NNN directory)')


def load_trial(run: Path) -> Tuple[TrialResult, Path]:
    """A recorded trial's result and where it was read: a result file, a trial directory, a
    run directory with one trial, or a trial's bag."""
    if not run.exists():
        raise RecordError(f'{run} does not exist')
    if is_bag(run):
        return result_from_bag(run), run
    source = find_result(run)
    result, problem = read_result(source)
    if result is None:
        raise RecordError(f'{source}: {problem or "no result"}')
    return result, source


def custom_data(bag: Path) -> Dict[str, str]:
    """A bag's custom data (metadata.yaml's ``custom_data``; {} if none)."""
    path = bag / 'metadata.yaml'
    text = read_text(path, 'a bag\'s metadata', MAX_METADATA_BYTES)
    try:
        info = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError) as exc:
        raise RecordError(f'{path} cannot be read: {str(exc)[:120]}') from None
    data = (info or {}).get('rosbag2_bagfile_information', {}) if isinstance(info, dict) else {}
    custom = data.get('custom_data') if isinstance(data, dict) else None
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def result_from_bag(bag: Path) -> TrialResult:
    """A trial's result as its bag keeps it: the coordinator's last published result, with
    what ran from the bag's metadata (each checked: RecordError)."""
    last = _last_result(bag)
    custom = custom_data(bag)
    if TRIAL_KEY not in custom:
        raise RecordError(f'{bag}: its metadata does not say what ran (no {TRIAL_KEY} in '
                          'custom_data: a bag recorded before bags kept it); use its trial '
                          'directory')
    ran = TrialRecord.from_json(custom[TRIAL_KEY], f'{bag}: {TRIAL_KEY}')
    # A run stopped before its end published no result: what ran is still known (it can be
    # drawn, and run again).
    result = (TrialResult.from_dict(parse_json(last, f'{bag}: its last {STATE_TOPIC}'),
                                    f'{bag}: its last {STATE_TOPIC}') if last else
              TrialResult.failure('interrupted', 'the run did not end while it was recorded '
                                  f'(no result on {STATE_TOPIC})', seed=ran.scenario_seed,
                                  belt_speed=ran.belt_speed))
    # (The coordinator's result has the seed and the belt speed; the trial runner added the
    # rest to the result file.)
    return replace(result.with_run(trial=ran.trial, code=ran.code),
                   parameters=dict(ran.parameters), scenario=dict(ran.scenario))


def _last_result(bag: Path) -> str:
    """The last result the coordinator published in a bag ('' if none)."""
    try:
        reader = open_reader(bag)
    except AnalysisError as exc:
        raise RecordError(str(exc)) from None
    last = ''
    try:
        states = [c for c in reader.connections if c.topic == STATE_TOPIC]
        if states:
            for _, _, msg in read_messages(reader, bag, states):
                text = getattr(msg, 'result_json', '')
                last = text if isinstance(text, str) and text else last
    except AnalysisError as exc:
        raise RecordError(str(exc)) from None
    finally:
        reader.close()
    return last
