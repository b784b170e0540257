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
import re
import subprocess
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

from ros_common.outputs import write_text
from trial_record.records import (
    MAX_COUNT,
    MAX_SIM_TIME_S,
    MAX_TEXT,
    Fields,
    RecordError,
    is_int,
    is_number,
    parse_json,
    read_text,
)
from world_description.world_config import WorldConfigError, parse_world

RESULT_FILE = 'result.json'      # in each trial's directory
# The CSV's columns, in order (``TrialResult.to_row``).
CSV_FIELDS = ('trial', 'scenario_seed', 'belt_speed', 'status', 'completion_time',
              'identification_rate', 'grasp_success_rate', 'handling_success_rate', 'identified',
              'identified_correct', 'picked', 'delivered', 'handled_verified', 'grasp_attempts',
              'grasp_successes', 'missed', 'failed', 'wall_time', 'parameters', 'message')
# The rates, each within 0..1 (NaN: a record no run made).
RATES = ('identification_rate', 'grasp_success_rate', 'handling_success_rate',
         'loader_grasp_rate', 'transport_grasp_rate', 'transport_rate')
# Metadata a record of the first layout kept at its top level (read into ``run``).
_FLAT_RUN_KEYS = ('trial', 'code', 'wall_time', 'cpu_seconds', 'node', 'ray_node', 'niceness',
                  'bag')
STATUSES = ('completed', 'incomplete', 'timeout', 'node_timeout', 'error', 'interrupted')
# The statuses of a trial that ended without an outcome of the cell: its processes could not
# start or failed, its nodes never came up, it ran past its wall time, or it was stopped. Such
# a trial says nothing about the cell: no rate counts it, and nothing reuses it.
DID_NOT_RUN = ('error', 'node_timeout', 'interrupted')
MODES = ('', 'lock-step', 'real-time')
COUNTS = ('total', 'identified', 'picked', 'delivered', 'grasp_attempts', 'grasp_successes',
          'missed', 'failed', 'loader_grasp_attempts', 'loader_grasp_successes',
          'transport_grasp_attempts', 'transport_grasp_successes', 'loaded', 'trips',
          'belt_stops', 'identified_correct', 'handled_verified')
# Counts that are parts of others (the rates divide one by the other).
_PARTS = (('grasp_successes', 'grasp_attempts'),
          ('loader_grasp_successes', 'loader_grasp_attempts'),
          ('transport_grasp_successes', 'transport_grasp_attempts'),
          ('identified_correct', 'total'), ('handled_verified', 'total'))
# The names records kept before the results named roles, not the paper's robot models (read
# as the roles' names: the loader was the paper's Zu 12, the transport its youBot).
_LEGACY_KEYS = {f'{model}_grasp_{what}': f'{role}_grasp_{what}'
                for model, role in (('zu12', 'loader'), ('youbot', 'transport'))
                for what in ('attempts', 'successes', 'rate')}
ROLES = ('loader', 'transport')
MAX_MESSAGE = 100_000               # characters of a result's message (longer ones are cut)
MAX_TRIAL = 1_000_000               # a trial's number in its plan
MAX_SEED = 2 ** 31 - 1              # (the simulator's scenario_seed is a 32-bit integer)
MAX_BELT_SPEED = 2.0                # [m/s] the world file's largest
TIME_STEP_RANGE = (1e-4, 0.05)      # [s] the simulator's time_step parameter's range
MAX_PARAMETERS = 16
PARAMETER_NAME = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$')
MAX_PATH_XY_M = 1e4                 # a path point's coordinates [m]
MAX_DRIVEN_PAST = 64                # joints driven past their speed limits, kept per trial
MAX_ROBOTS = 16                     # youBots a result tells apart


class ResultError(RecordError):
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
    # A sweep's point: the parameters set for this trial (studies.sweep), else {}.
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
    loader_grasp_attempts: int = 0
    loader_grasp_successes: int = 0
    transport_grasp_attempts: int = 0
    transport_grasp_successes: int = 0
    loaded: int = 0
    trips: int = 0
    belt_stops: int = 0
    # What the ground truth says (results.score).
    identified_correct: int = 0
    handled_verified: int = 0
    identification_rate: float = math.nan
    grasp_success_rate: float = math.nan
    handling_success_rate: float = math.nan
    loader_grasp_rate: float = math.nan
    transport_grasp_rate: float = math.nan
    transport_rate: float = math.nan
    not_at_destination: List[Dict[str, Any]] = field(default_factory=list)
    # What the run went through.
    materials: List[Dict[str, Any]] = field(default_factory=list)
    identifications: List[Dict[str, Any]] = field(default_factory=list)
    final_materials: List[Dict[str, Any]] = field(default_factory=list)
    peak_joint_speed: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    # The joints the simulator had to brake back to their speed limits because the world drove
    # them past (each its worst: robot, joint, ratio, speed, limit, brake, time, count).
    joints_driven_past: List[Dict[str, Any]] = field(default_factory=list)
    odometry_age: Optional[Dict[str, float]] = None      # real-time runs only
    # A cell with several mobile bases: how near two of them came, footprint to footprint, by
    # the simulator's ground truth: {distance [m], time [s], robots: [a, b]}.
    closest_bases: Optional[Dict[str, Any]] = None
    # A cell with several youBots: each one's share (scoring.fleet_shares): trips, carried,
    # delivered, distance [m], busy and waiting [s], and its path (as youbot_path).
    transports: Optional[Dict[str, Dict[str, Any]]] = None
    # Each robot's grasps, by its name: its role (loader or transport), attempts, successes
    # (a loader's picks off the belt, a transport's unloads of its plate). None: a record
    # written before robots were told apart.
    robot_grasps: Optional[Dict[str, Dict[str, Any]]] = None
    youbot_path: List[List[float]] = field(default_factory=list)
    events: List[List[Any]] = field(default_factory=list)
    states: List[List[Any]] = field(default_factory=list)
    run: RunInfo = field(default_factory=RunInfo)

    def __post_init__(self) -> None:
        # (What is written must read back: a message is cut to what the reader takes.)
        if len(self.message) > MAX_MESSAGE:
            self.message = self.message[:MAX_MESSAGE - 1] + '\u2026'

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

    @property
    def ran(self) -> bool:
        """The trial ran the cell to an outcome (completed or not): evidence about the cell."""
        return self.status not in DID_NOT_RUN

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
        for key in ('odometry_age', 'closest_bases', 'transports', 'robot_grasps'):
            if out[key] is None:
                del out[key]
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
        write_text(path, self.to_json())

    @classmethod
    def from_dict(cls, data: Any, what: str = 'the result') -> 'TrialResult':
        """A record read back (``to_dict``'s layout, or the first layout, which kept the run's
        metadata at its top level), every field typed and ranged; ResultError says which field
        makes it unusable."""
        if not isinstance(data, Mapping):
            raise ResultError(f'{what}: not a trial result (a JSON {type(data).__name__})')
        data = dict(data)
        run = data.pop('run', {})
        if not isinstance(run, Mapping):
            raise ResultError(f'{what}: run is not a mapping')
        run = dict(run)
        for key in _FLAT_RUN_KEYS:
            if key in data:
                if key in run and run[key] != data[key]:
                    raise ResultError(f'{what}: {key} is {data[key]!r:.40} and, in its run, '
                                      f'{run[key]!r:.40}')
                run[key] = data.pop(key)
        data.pop('cpu_seconds_self', None)
        for legacy, key in _LEGACY_KEYS.items():
            if legacy in data:
                if key in data:
                    raise ResultError(f'{what}: has both {legacy} and {key} (its name now)')
                data[key] = data.pop(legacy)
        try:
            return cls(**_outcome(Fields(data, what)), run=_run_info(Fields(run, f'{what}: run')))
        except ResultError:
            raise
        except RecordError as exc:
            raise ResultError(str(exc)) from None


def _outcome(f: Fields) -> Dict[str, Any]:
    """The fields of a result but its run, checked."""
    f.only([x.name for x in fields(TrialResult) if x.name != 'run'])
    out: Dict[str, Any] = {
        'status': f.text('status', choices=STATUSES),
        'completion_time': f.number('completion_time', 0.0, MAX_SIM_TIME_S, math.nan, nan=True),
        'message': f.text('message', '', limit=MAX_MESSAGE),
        'scenario_seed': f.integer('scenario_seed', -1, MAX_SEED, None, none=True),
        'belt_speed': f.number('belt_speed', 0.0, MAX_BELT_SPEED, math.nan, nan=True),
        'mode': f.text('mode', '', choices=MODES),
        'parameters': check_parameters(f),
        'scenario': check_scenario(f),
        'not_at_destination': f.entries('not_at_destination', []),
        'materials': _materials(f),
        'identifications': f.entries('identifications', []),
        'final_materials': f.entries('final_materials', []),
        'peak_joint_speed': _peaks(f),
        'joints_driven_past': _driven_past(f),
        'youbot_path': _path(f),
        'events': _rows(f, 'events', (_time, str, str, int, str, str)),
        'states': _rows(f, 'states', (_time, str, str)),
    }
    out.update({key: f.integer(key, 0, MAX_COUNT, 0) for key in COUNTS})
    for part, whole in _PARTS:
        if out[part] > out[whole]:
            raise f.fail(part, f'is {out[part]}, more than {whole} ({out[whole]})')
    out.update({key: f.number(key, 0.0, 1.0, math.nan, nan=True) for key in RATES})
    if f.has('odometry_age') and f.data['odometry_age'] is not None:
        out['odometry_age'] = f.numbers('odometry_age', -MAX_SIM_TIME_S, MAX_SIM_TIME_S)
    if f.has('closest_bases') and f.data['closest_bases'] is not None:
        c = Fields(f.data['closest_bases'], f'{f.what}: closest_bases')
        c.only(('distance', 'time', 'robots'))
        robots = c.items('robots', limit=2)
        if len(robots) != 2 or not all(isinstance(r, str) and 0 < len(r) <= 256
                                       for r in robots):
            raise c.fail('robots', 'is not two robots\' names')
        out['closest_bases'] = {'distance': c.number('distance', 0.0, MAX_PATH_XY_M),
                                'time': c.number('time', -MAX_SIM_TIME_S, MAX_SIM_TIME_S),
                                'robots': list(robots)}
    if f.has('transports') and f.data['transports'] is not None:
        out['transports'] = _transports(f)
    if f.has('robot_grasps') and f.data['robot_grasps'] is not None:
        out['robot_grasps'] = _robot_grasps(f)
    return out


def _robot_name(f: Fields, key: str, robot: Any) -> str:
    if not isinstance(robot, str) or not 0 < len(robot) <= 256:
        raise f.fail(key, f'name {str(robot)[:40]!r}, which is no robot\'s name')
    return robot


def _robot_grasps(f: Fields) -> Dict[str, Dict[str, Any]]:
    robots = f.record('robot_grasps', {})
    if len(robots.data) > MAX_ROBOTS + 1:
        raise f.fail('robot_grasps', f'are of {len(robots.data)} robots, more than '
                     f'{MAX_ROBOTS + 1}')
    out = {}
    for robot in robots.data:
        r = robots.record(_robot_name(f, 'robot_grasps', robot))
        r.only(('role', 'attempts', 'successes'))
        grasps: Dict[str, Any] = {'role': r.text('role', choices=ROLES),
                                  'attempts': r.integer('attempts', 0, MAX_COUNT),
                                  'successes': r.integer('successes', 0, MAX_COUNT)}
        if grasps['successes'] > grasps['attempts']:
            raise r.fail('successes', f'are {grasps["successes"]}, more than its attempts '
                         f'({grasps["attempts"]})')
        out[robot] = grasps
    return out


def _transports(f: Fields) -> Dict[str, Dict[str, Any]]:
    shares = f.record('transports', {})
    if not 0 < len(shares.data) <= MAX_ROBOTS:
        raise f.fail('transports', f'are {len(shares.data)} youBots, not 1 to {MAX_ROBOTS}')
    out = {}
    for robot in shares.data:
        r = shares.record(_robot_name(f, 'transports', robot))
        r.only(('trips', 'carried', 'delivered', 'distance', 'busy', 'waiting', 'path'))
        share: Dict[str, Any] = {key: r.integer(key, 0, MAX_COUNT)
                                 for key in ('trips', 'carried', 'delivered')}
        if share['delivered'] > share['carried']:
            raise r.fail('delivered', f'is {share["delivered"]}, more than carried '
                         f'({share["carried"]})')
        share['distance'] = r.number('distance', 0.0, MAX_PATH_XY_M * 100)
        share.update({key: r.number(key, 0.0, MAX_SIM_TIME_S) for key in ('busy', 'waiting')})
        share['path'] = _path(r, 'path')
        out[robot] = share
    return out


def _run_info(f: Fields) -> RunInfo:
    f.only([x.name for x in fields(RunInfo)])
    return RunInfo(trial=f.integer('trial', 0, MAX_TRIAL, None, none=True),
                   code=f.text('code', 'unknown', limit=200),
                   wall_time=f.number('wall_time', 0.0, 1e8, math.nan, nan=True),
                   cpu_seconds=f.numbers('cpu_seconds', 0.0, 1e8, {}),
                   node=f.text('node', '', limit=1000),
                   ray_node=f.text('ray_node', '', limit=1000),
                   niceness=f.integer('niceness', -20, 19, None, none=True),
                   bag=f.text('bag', '', limit=4096))


def check_parameters(f: Fields) -> Dict[str, float]:
    """A sweep point's (or a re-run's) parameters: numbers by their names (belt_speed, or a
    number of the world file by its path); each is checked against the world when used."""
    values = f.numbers('parameters', -1e12, 1e12, {})
    bad = [name for name in values if len(name) > 200 or not PARAMETER_NAME.match(name)]
    if bad or len(values) > MAX_PARAMETERS:
        raise f.fail('parameters', f'are not at most {MAX_PARAMETERS} numbers by name '
                     f'({bad[0][:40]!r} is no name)' if bad else
                     f'are {len(values)} (at most {MAX_PARAMETERS})')
    return values


def check_scenario(f: Fields) -> Dict[str, Any]:
    """What it takes to run a trial again: the world as given, the world file as it was (a
    world the reader of world files takes), the physics step."""
    s = f.record('scenario', {})
    s.only(('world', 'world_data', 'time_step'))
    out: Dict[str, Any] = {}
    for key in s.data:                   # (in their order: a world's keys are part of it)
        if key == 'world':
            out[key] = s.text(key, limit=4096)
        elif key == 'time_step':
            out[key] = s.number(key, *TIME_STEP_RANGE)
        else:
            data = s.record(key).data
            try:
                parse_world(data, f'{s.what}: world_data')
            except WorldConfigError as exc:
                raise ResultError(str(exc)) from None
            except RecursionError:
                raise ResultError(f'{s.what}: world_data is nested too deeply') from None
            out[key] = dict(data)
    return out


def _materials(f: Fields) -> List[Dict[str, Any]]:
    """What became of each material (the report names a failed one by id, colour, status)."""
    out = f.entries('materials', [])
    for k, m in enumerate(out):
        entry = Fields(m, f'{f.what}: materials[{k}]')
        entry.integer('id', -1, MAX_COUNT)
        entry.text('color')
        entry.text('status')
        entry.text('failure', '')
    return out


def _peaks(f: Fields) -> Dict[str, Dict[str, Any]]:
    out = {}
    peaks = f.record('peak_joint_speed', {})
    for arm in peaks.data:
        p = peaks.record(arm)
        p.number('fraction_of_limit', 0.0, 1e6)
        p.text('joint', '')
        if p.has('time') and p.data['time'] is not None:
            p.number('time', -MAX_SIM_TIME_S, MAX_SIM_TIME_S, nan=True)
        out[arm] = dict(p.data)
    return out


def _driven_past(f: Fields) -> List[Dict[str, Any]]:
    out = []
    for k, item in enumerate(f.items('joints_driven_past', [], limit=MAX_DRIVEN_PAST)):
        d = Fields(item, f'{f.what}: joints_driven_past[{k}]')
        d.only(('robot', 'joint', 'ratio', 'speed', 'limit', 'brake', 'time', 'count'))
        out.append({'robot': d.text('robot', limit=256), 'joint': d.text('joint', limit=256),
                    'ratio': d.number('ratio', 0.0, 1e6), 'speed': d.number('speed', 0.0, 1e6),
                    'limit': d.number('limit', 0.0, 1e6), 'brake': d.number('brake', 0.0, 1e9),
                    'time': d.number('time', -MAX_SIM_TIME_S, MAX_SIM_TIME_S),
                    'count': d.integer('count', 0, 10**9)})
    return out


def _path(f: Fields, key: str = 'youbot_path') -> List[List[float]]:
    points = f.items(key, [])
    for k, point in enumerate(points):
        if not (isinstance(point, list) and len(point) == 2 and all(
                is_number(v) and abs(v) <= MAX_PATH_XY_M for v in point)):
            raise f.fail(f'{key}[{k}]', f'is not [x, y] within {MAX_PATH_XY_M:g} m')
    return [[float(x), float(y)] for x, y in points]


def _time(value: Any) -> bool:
    return is_number(value) and abs(value) <= MAX_SIM_TIME_S


def _rows(f: Fields, key: str, kinds: Tuple[Any, ...]) -> List[List[Any]]:
    """A list of rows of a fixed shape: an event (time, kind, robot, material, colour,
    detail) or a state change (time, machine, state)."""
    rows = f.items(key, [])
    for k, row in enumerate(rows):
        ok = isinstance(row, list) and len(row) == len(kinds) and all(
            kind(v) if callable(kind) and kind is _time else
            (is_int(v) if kind is int else isinstance(v, kind) and len(v) <= MAX_TEXT)
            for kind, v in zip(kinds, row))
        if not ok:
            raise f.fail(f'{key}[{k}]', 'is not a row of ' + ', '.join(
                'time' if kind is _time else kind.__name__ for kind in kinds))
    return rows


def read_result(path: Path) -> Tuple[Optional[TrialResult], Optional[str]]:
    """A trial's result and None, or None and why it cannot be used (None, None: no file)."""
    if not path.exists() and not path.is_symlink():
        return None, None
    try:
        data = parse_json(read_text(path, 'a trial result'), str(path))
        return TrialResult.from_dict(data, str(path)), None
    except RecordError as exc:
        text = str(exc)
        prefix = f'{path}: '
        return None, text[len(prefix):] if text.startswith(prefix) else text


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
