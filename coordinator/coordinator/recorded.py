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
from dataclasses import replace
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

import yaml

from coordinator.trial_result import RESULT_FILE, ResultError, TrialResult, read_result
from recording.analysis import AnalysisError, open_reader

TRIAL_KEY = 'robot_sim.trial'
STATE_TOPIC = '/coordinator_node/state'


class RecordError(ValueError):
    """A run that cannot be read as a trial; the message is the line to print."""


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
    try:
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise RecordError(f'{bag}: its metadata.yaml cannot be read: {exc}') from None
    data = (info or {}).get('rosbag2_bagfile_information', {}) if isinstance(info, dict) else {}
    custom = data.get('custom_data') if isinstance(data, dict) else None
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def result_from_bag(bag: Path) -> TrialResult:
    """A trial's result as its bag keeps it: the coordinator's last published result, with
    what ran from the bag's metadata."""
    try:
        reader = open_reader(bag)
    except AnalysisError as exc:
        raise RecordError(str(exc)) from None
    try:
        last = ''
        states = [c for c in reader.connections if c.topic == STATE_TOPIC]
        for connection, _, raw in reader.messages(connections=states):
            text = str(getattr(reader.deserialize(raw, connection.msgtype), 'result_json', ''))
            last = text or last
    finally:
        reader.close()
    custom = custom_data(bag)
    if TRIAL_KEY not in custom:
        raise RecordError(f'{bag}: its metadata does not say what ran (no {TRIAL_KEY} in '
                          'custom_data: a bag recorded before bags kept it); use its trial '
                          'directory')
    try:
        ran = json.loads(custom[TRIAL_KEY])
    except ValueError as exc:
        raise RecordError(f'{bag}: {TRIAL_KEY}: {str(exc)[:120]}') from None
    if not isinstance(ran, dict):
        raise RecordError(f'{bag}: {TRIAL_KEY} is not a JSON object')
    try:
        # A run stopped before its end published no result: what ran is still known (it can
        # be drawn, and run again).
        result = (TrialResult.from_dict(json.loads(last)) if last else TrialResult.failure(
            'interrupted', f'the run did not end while it was recorded (no result on '
            f'{STATE_TOPIC})', seed=ran.get('scenario_seed'),
            belt_speed=float(ran.get('belt_speed', math.nan))))
    except (ValueError, TypeError, ResultError) as exc:
        raise RecordError(f'{bag}: {str(exc)[:120]}') from None
    # (The coordinator's result has the seed and the belt speed; the trial runner added the
    # rest to the result file.)
    return replace(result.with_run(trial=ran.get('trial'), code=str(ran.get('code', ''))),
                   parameters=dict(ran.get('parameters') or {}),
                   scenario=dict(ran.get('scenario') or {}))
