"""One trial's result record, as ``result.json`` holds it and the CSV and the report read it.

What the run did (the coordinator's counts, checked against the simulator's ground truth by
``results.score``) is built once, by ``results.build_result``; the run's own metadata (which
trial, the code, wall time, CPU time, the host) is a block of its own, ``run``, filled in by
whoever ran it (the trial runner, or the coordinator node run by hand). A record that could not
be made by a run (the trial failed to start, was interrupted, its Ray task died) is made by
``TrialResult.failure``. ``to_row()`` is the record's row of ``trials.csv``.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

RESULT_FILE = 'result.json'      # in each trial's directory
# The CSV's columns, in order (``TrialResult.to_row``).
CSV_FIELDS = ('trial', 'scenario_seed', 'belt_speed', 'status', 'completion_time',
              'identification_rate', 'grasp_success_rate', 'handling_success_rate', 'identified',
              'identified_correct', 'picked', 'delivered', 'handled_verified', 'grasp_attempts',
              'grasp_successes', 'missed', 'failed', 'wall_time', 'parameters', 'message')
# The rates, each within 0..1 (NaN: a record no run made).
RATES = ('identification_rate', 'grasp_success_rate', 'handling_success_rate',
         'zu12_grasp_rate', 'youbot_grasp_rate', 'transport_rate')
# Metadata a record of the first layout kept at its top level (read into ``run``).
_FLAT_RUN_KEYS = ('trial', 'code', 'wall_time', 'cpu_seconds', 'node', 'ray_node', 'niceness',
                  'bag')


class ResultError(ValueError):
    """A record that is not a trial's result, and why."""


@dataclass
class RunInfo:
    """The run's own metadata: not what the run did, but which trial it was and what it cost."""
    trial: Optional[int] = None          # its number in the campaign's plan (None: run by hand)
    code: str = 'unknown'                # the code version (trial_run.code_version)
    wall_time: float = math.nan          # [s] from the first process started to the last gone
    cpu_seconds: Dict[str, float] = field(default_factory=dict)     # per process [s]
    node: str = ''                       # the host it ran on, where that is not this one (Ray)
    ray_node: str = ''                   # its Ray node id (Ray)
    niceness: Optional[int] = None       # its processes' niceness (Ray)
    bag: str = ''                        # host:path of its bag, where left on a worker (Ray)


@dataclass
class TrialResult:
    """A trial's result: the run's scenario, its outcome and figures, what it went through, and
    its metadata (``run``). Rates are fractions; times are simulated seconds from the start."""
    status: str                          # completed, incomplete, timeout, node_timeout, error,
    #                                      interrupted
    completion_time: float = math.nan
    message: str = ''
    # The scenario.
    scenario_seed: Optional[int] = None
    belt_speed: float = math.nan         # [m/s]
    mode: str = ''                       # lock-step or real-time
    # A sweep's point: the parameters set for this trial (coordinator.sweep), else {}.
    parameters: Dict[str, float] = field(default_factory=dict)
    # What it takes to run the trial again (run_trials --rerun): the world as given, the world
    # file as it was (one mapping, what it extends merged in), the physics step.
    scenario: Dict[str, Any] = field(default_factory=dict)
    # What the coordinator counted.
    total: int = 0
    identified: int = 0
    picked: int = 0
    delivered: int = 0
    grasp_attempts: int = 0
    grasp_successes: int = 0
    missed: int = 0
    failed: int = 0
    zu12_grasp_attempts: int = 0
    zu12_grasp_successes: int = 0
    youbot_grasp_attempts: int = 0
    youbot_grasp_successes: int = 0
    loaded: int = 0
    trips: int = 0
    belt_stops: int = 0
    # What the ground truth says (results.score).
    identified_correct: int = 0
    handled_verified: int = 0
    identification_rate: float = math.nan
    grasp_success_rate: float = math.nan
    handling_success_rate: float = math.nan
    zu12_grasp_rate: float = math.nan
    youbot_grasp_rate: float = math.nan
    transport_rate: float = math.nan
    not_at_destination: List[Dict[str, Any]] = field(default_factory=list)
    # What the run went through.
    materials: List[Dict[str, Any]] = field(default_factory=list)
    identifications: List[Dict[str, Any]] = field(default_factory=list)
    final_materials: List[Dict[str, Any]] = field(default_factory=list)
    peak_joint_speed: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    odometry_age: Optional[Dict[str, float]] = None      # real-time runs only
    youbot_path: List[List[float]] = field(default_factory=list)
    events: List[List[Any]] = field(default_factory=list)
    states: List[List[Any]] = field(default_factory=list)
    run: RunInfo = field(default_factory=RunInfo)

    @classmethod
    def failure(cls, status: str, message: str, trial: Optional[int] = None,
                seed: Optional[int] = None, belt_speed: float = math.nan,
                run: Optional[RunInfo] = None) -> 'TrialResult':
        """The record of a trial no run finished (status: error, interrupted)."""
        info = run if run is not None else RunInfo()
        if trial is not None:
            info = replace(info, trial=trial)
        return cls(status=status, message=message, scenario_seed=seed, belt_speed=belt_speed,
                   run=info)

    @property
    def trial(self) -> Optional[int]:
        return self.run.trial

    def with_run(self, **changes: Any) -> 'TrialResult':
        """The same result, its metadata changed (``RunInfo``'s fields)."""
        return replace(self, run=replace(self.run, **changes))

    def differences(self, other: 'TrialResult') -> List[str]:
        """The fields in which two runs' outcomes differ, their metadata (``run``: code, wall
        time, CPU time, host) and ``scenario`` (where the world file was) left out: [] for two
        runs of the same trial that went the same way (a lock-step trial re-run, or run in the
        container image). NaN equals NaN here."""
        mine, theirs = self.to_dict(), other.to_dict()
        return [f.name for f in fields(self) if f.name not in ('run', 'scenario')
                and json.dumps(mine.get(f.name), sort_keys=True)
                != json.dumps(theirs.get(f.name), sort_keys=True)]

    def to_dict(self) -> Dict[str, Any]:
        out = asdict(self)
        if out['odometry_age'] is None:
            del out['odometry_age']
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    def to_row(self) -> Dict[str, Any]:
        """Its row of ``trials.csv`` (CSV_FIELDS)."""
        flat = {**self.to_dict(), 'trial': self.run.trial, 'wall_time': self.run.wall_time,
                'parameters': ' '.join(f'{k}={v:g}' for k, v in self.parameters.items())}
        return {k: '' if flat[k] is None else flat[k] for k in CSV_FIELDS}

    def write(self, path: Path) -> None:
        """Written whole or not at all (a crash mid-write leaves no half a record)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        scratch = path.with_name(path.name + '.new')
        scratch.write_text(self.to_json())
        os.replace(scratch, path)

    @classmethod
    def from_dict(cls, data: Any) -> 'TrialResult':
        """A record read back (``to_dict``'s layout, or the first layout, which kept the run's
        metadata at its top level); ResultError says what makes it unusable."""
        if not isinstance(data, Mapping):
            raise ResultError(f'not a trial result (a JSON {type(data).__name__})')
        data = dict(data)
        run = data.pop('run', None)
        run = dict(run) if isinstance(run, Mapping) else {}
        for key in _FLAT_RUN_KEYS:
            if key in data:
                if key in run and run[key] != data[key]:
                    raise ResultError(f'{key} is {data[key]!r:.40} and, in its run, '
                                      f'{run[key]!r:.40}')
                run[key] = data.pop(key)
        data.pop('cpu_seconds_self', None)
        _check(data, run)
        known = {f.name for f in fields(cls)} - {'run'}
        info = RunInfo(**{k: v for k, v in run.items()
                          if k in {f.name for f in fields(RunInfo)}})
        return cls(**{k: v for k, v in data.items() if k in known}, run=info)


def _check(data: Dict[str, Any], run: Dict[str, Any]) -> None:
    if not isinstance(data.get('status'), str) or not data['status']:
        raise ResultError('no status')
    for key, where in (('trial', run), ('scenario_seed', data)):
        number: Any = where.get(key)
        if key in where and number is not None and not (is_int(number) and number >= 0):
            raise ResultError(f'{key} is {number!r:.40}, not an integer >= 0')
    for key, where in (('belt_speed', data), ('completion_time', data), ('wall_time', run)):
        if key in where and not is_number(where[key]):
            raise ResultError(f'{key} is {where[key]!r:.40}, not a number')
    for key in RATES:
        value: Any = data.get(key)
        if key in data and not (is_number(value) and (
                math.isnan(value) or 0.0 <= value <= 1.0)):
            raise ResultError(f'{key} is {value!r:.40}, not a rate within 0..1')
    if not isinstance(data.get('scenario', {}), Mapping):
        raise ResultError(f'scenario is {data["scenario"]!r:.40}, not a mapping')
    parameters = data.get('parameters', {})
    if not isinstance(parameters, Mapping) or not all(
            isinstance(k, str) and is_number(v) for k, v in parameters.items()):
        raise ResultError(f'parameters is {parameters!r:.40}, not numbers by name')
    cpu = run.get('cpu_seconds', {})
    if not isinstance(cpu, Mapping) or not all(is_number(v) for v in cpu.values()):
        raise ResultError(f'cpu_seconds is {cpu!r:.40}, not seconds per process')


def read_result(path: Path) -> Tuple[Optional[TrialResult], Optional[str]]:
    """A trial's result and None, or None and why it cannot be used (None, None: no file)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None, None
    except (OSError, UnicodeDecodeError) as exc:
        return None, f'cannot be read: {exc}'
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        return None, f'not JSON: {str(exc)[:80]}'
    try:
        return TrialResult.from_dict(data), None
    except ResultError as exc:
        return None, str(exc)


def code_version() -> str:
    """The code a trial runs: the checkout's commit, with ``-dirty`` when a tracked file outside
    docs/ and the Markdown files differs from it (results written into docs/ do not count).
    Outside a git checkout: ``ROBOT_SIM_CODE_VERSION`` (the container image sets it to the
    commit it was built from), else 'unknown'. ``--resume`` reuses a result only of the same
    code."""
    here = str(Path(__file__).resolve().parent)

    def git(*args: str) -> Optional[str]:
        try:
            out = subprocess.run(['git', '-C', here, *args], capture_output=True, text=True,
                                 timeout=30.0)
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip() if out.returncode == 0 else None
    commit, root = git('rev-parse', '--short=12', 'HEAD'), git('rev-parse', '--show-toplevel')
    if not commit or not root:
        return os.environ.get('ROBOT_SIM_CODE_VERSION', '').strip() or 'unknown'
    changed = git('-C', root, 'status', '--porcelain', '--untracked-files=no', '--', '.',
                  ':(exclude)docs', ':(exclude)*.md')
    return commit + ('-dirty' if changed is None or changed else '')


def is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
