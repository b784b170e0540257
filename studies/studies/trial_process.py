"""Running one trial: its processes as one group on a DDS domain leased for it, its result and
the code it ran. ``run_trials`` (trials.py) runs campaigns of them on this machine, and
``trials_ray.py`` on a Ray cluster; both use this module, which uses neither."""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, Optional, Set, TypedDict

from ros_common.dds import hold_free_domain, with_profile
from ros_common.outputs import OutputError, inner_dir, make_dir, open_new
from studies.progress import read_progress
from studies.recorded import bag_metadata
from studies.sweep import SweepError, point_world
from studies.trial_graph import TIME_STEP, pipeline_graph
from trial_record.result import (
    RESULT_FILE,
    RunInfo,
    TrialResult,
    code_version,
    read_result,
)
from world_description import PIPELINE_CELL
from world_description.resources import ResourceError, resolve_resource
from world_description.world_config import WorldConfigError, world_data

PROGRESS_FILE = 'progress.json'
OUTCOME_FILE = 'coordinator_result.json'   # the coordinator's record, before the runner's
RECORDER_READY = 'recorder.ready'     # written by the recorder once it records /clock
# The highest DDS domain id (Fast DDS's ports for 233 and above exceed 65535 on Linux).
MAX_DOMAIN = 232
# Lock files that keep two trials on one machine off the same domain (run_trials processes,
# Ray workers): one per domain, held while a trial runs.
DOMAIN_LOCK_DIR = Path(tempfile.gettempdir()) / 'run_trials-domains'
# Process groups of the trials running now (stopped when the runner is interrupted).
ACTIVE_GROUPS: Set[int] = set()
# Set when the user stops the campaign: a trial stopped then has no result of its own.
INTERRUPTED = threading.Event()


def run_trial(trial: int, seed: int, belt_speed: float, domain_id: int, out_dir: Path,
              wall_timeout: float = 900.0, record: bool = False, code: str = '',
              world: str = PIPELINE_CELL, time_step: float = TIME_STEP,
              parameters: Optional[Dict[str, float]] = None) -> TrialResult:
    """One trial as a process group; returns its result (or a failure record), written to
    the trial's ``result.json``. ``parameters``: a sweep's point (its world's values go into
    the trial's own ``world.yaml``)."""
    trial_dir = out_dir / f'trial_{trial:03d}'
    try:
        make_dir(out_dir, 'the campaign\'s directory')    # (a Ray worker's: made here)
        inner_dir(trial_dir, 'the trial\'s directory')
    except OutputError as exc:        # (nothing can be written for it: the result says why)
        return replace(TrialResult.failure('error', str(exc), trial, seed, belt_speed),
                       parameters=dict(parameters or {}))
    result_file = trial_dir / RESULT_FILE
    outcome_file = trial_dir / OUTCOME_FILE
    for stale in (result_file, outcome_file, trial_dir / PROGRESS_FILE):
        stale.unlink(missing_ok=True)
    if parameters:
        try:
            world = point_world(world, parameters, trial_dir)
        except SweepError as exc:         # (checked before the campaign; a worker may differ)
            failed = replace(TrialResult.failure('error', str(exc), trial, seed, belt_speed),
                             parameters=dict(parameters))
            failed.write(result_file)
            return failed
    env = with_profile({**os.environ, 'ROS_DOMAIN_ID': str(domain_id),
                        'ROS_AUTOMATIC_DISCOVERY_RANGE': os.environ.get(
                            'ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')})
    code = code or code_version()
    ran = scenario(world, time_step)
    graph = pipeline_graph(seed, belt_speed, world=world, result_file=outcome_file,
                           progress_file=trial_dir / PROGRESS_FILE,
                           record_dir=trial_dir if record else None, time_step=time_step,
                           recorder_ready=trial_dir / RECORDER_READY,
                           bag_metadata=bag_metadata(trial, seed, belt_speed, code, ran,
                                                     parameters))
    commands = {node.name: node.command() for node in graph}
    procs: Dict[str, 'subprocess.Popen[bytes]'] = {}
    cpu: Dict[str, float] = {}
    group: Optional[int] = None
    not_started = ''                # why a process could not start (its executable gone)
    start = time.monotonic()
    try:
        # (A user's stop is looked for before each process starts and while each is waited
        # for: a trial being set up when the campaign is stopped starts nothing more.)
        for name, argv in commands.items():
            if INTERRUPTED.is_set():
                break
            if name == 'coordinator_node' and 'recorder' in procs:
                # (The recorder hears the first /clock: the coordinator steps only after it.)
                _wait_for_file(trial_dir / RECORDER_READY, 30.0)
            log = open_new(trial_dir / f'{name}.log')
            try:
                procs[name] = subprocess.Popen(
                    argv, stdout=log, stderr=subprocess.STDOUT, env=env,
                    preexec_fn=_trial_process(0 if group is None else group))
            except OSError as exc:
                # (A workspace rebuilt under a running campaign: the trial fails, the others
                # go on.)
                not_started = (f'cannot start {name} ({argv[0]}): {exc.strerror or exc}; is '
                               'the workspace built and sourced (source scripts/env.sh)?')
                log.write(not_started + '\n')
                break
            finally:
                log.close()
            group = procs[name].pid if group is None else group
            ACTIVE_GROUPS.add(group)
        coordinator = procs.get('coordinator_node')
        deadline = time.monotonic() + wall_timeout
        while (coordinator is not None and coordinator.poll() is None
               and time.monotonic() < deadline and not INTERRUPTED.wait(0.2)):
            pass
        late = (coordinator is not None and coordinator.poll() is None
                and time.monotonic() >= deadline)
        cpu = {name: _cpu_seconds(p.pid) for name, p in procs.items() if p.poll() is None}
    finally:
        _stop_group(group, procs, interrupted=INTERRUPTED.is_set())
        ACTIVE_GROUPS.discard(group)
    run = RunInfo(trial=trial, code=code,
                  wall_time=time.monotonic() - start, cpu_seconds=cpu)
    coordinator = procs.get('coordinator_node')
    if not_started:
        failed = replace(TrialResult.failure('error', not_started, trial, seed, belt_speed, run),
                         parameters=dict(parameters or {}), scenario=ran)
        failed.write(result_file)
        return failed
    result = _record(trial_dir, run, seed, belt_speed,
                     coordinator.returncode if coordinator is not None else None,
                     wall_timeout if late else None)
    result = replace(result, parameters=dict(parameters or {}), scenario=ran)
    result.write(result_file)
    outcome_file.unlink(missing_ok=True)
    return result


def scenario(world: str, time_step: float) -> Dict[str, Any]:
    """A trial's ``scenario``: the world as given, and as it was (``world_data``)."""
    out: Dict[str, Any] = {'world': world, 'time_step': time_step}
    try:
        out['world_data'] = world_data(resolve_resource(world))
    except (WorldConfigError, ResourceError) as exc:     # (checked before the trial ran)
        out['world_problem'] = str(exc)
    return out


def _record(trial_dir: Path, run: RunInfo, seed: int, belt_speed: float,
            exit_code: Optional[int], late: Optional[float] = None) -> TrialResult:
    """The trial's record: the coordinator's, with the run's metadata; or, without one, why
    (``late``: the wall timeout it ran past, and was stopped at)."""
    outcome, problem = read_result(trial_dir / OUTCOME_FILE)
    if outcome is not None:
        # (The coordinator measured its own CPU time; the runner the others', still running.)
        return outcome.with_run(**{**asdict(run), 'cpu_seconds': {
            **run.cpu_seconds, **outcome.run.cpu_seconds}})
    if INTERRUPTED.is_set():     # (stopped by the user: --resume runs it again)
        return TrialResult.failure('interrupted', 'the campaign was interrupted', run.trial,
                                   seed, belt_speed, run)
    if late is not None:
        # (It said only "no result (coordinator exit 0)", the coordinator stopped cleanly.)
        progress = read_progress(trial_dir / PROGRESS_FILE) or {}
        where = (f' at {progress["sim_time"]:.1f} s simulated' if 'sim_time' in progress
                 else '')
        return TrialResult.failure(
            'error', f'stopped at its wall timeout ({late:g} s of wall time){where}: the '
            f'machine ran it too slowly (--wall-timeout gives a trial longer); see {trial_dir}',
            run.trial, seed, belt_speed, run)
    return TrialResult.failure(
        'error', f'no result (coordinator exit {exit_code}'
        + (f'; its result file: {problem}' if problem else '') + f'); see {trial_dir}',
        run.trial, seed, belt_speed, run)


class _Trial(TypedDict):
    trial: int
    seed: int
    belt_speed: float


class PlanItem(_Trial, total=False):
    """A trial of a campaign's plan; in a sweep, with its point's ``parameters``
    (studies.sweep: the world's are written into the trial's own world file)."""
    parameters: Dict[str, float]


@contextmanager
def domain_lease(first: int) -> Iterator[int]:
    """The first DDS domain from ``first`` on that no other trial on this machine holds, held
    (ros_common.dds.hold_free_domain) until the block ends; a crashed holder's lock goes with
    its process."""
    held = hold_free_domain(range(first, MAX_DOMAIN + 1), DOMAIN_LOCK_DIR)
    if held is None:
        raise RuntimeError(f'no free DDS domain in {first}-{MAX_DOMAIN} on this machine')
    domain, lock = held
    try:
        yield domain
    finally:
        lock.close()               # (releases the lock)


def run_leased_trial(item: PlanItem, out_dir: Path, options: Dict[str, Any]) -> TrialResult:
    """``run_trial`` for a plan item on a DDS domain of its own (``options``: domain_base,
    wall_timeout, record, code, world, time_step)."""
    opts = dict(options)
    with domain_lease(opts.pop('domain_base')) as domain:
        if 'parameters' in item:                    # (a sweep's point)
            opts['parameters'] = item['parameters']
        return run_trial(item['trial'], item['seed'], item['belt_speed'], domain, out_dir,
                         **opts)


# Linux's prctl, looked up here: a child between fork and exec must not load libraries.
_PRCTL = ctypes.CDLL(None, use_errno=True).prctl if sys.platform.startswith('linux') else None


def _trial_process(group: int) -> Callable[[], None]:
    """What a trial's process does in the child before exec: join the trial's process group
    (``group``, or 0: a new one led by itself), so that a trial's processes are stopped
    together and never mixed with another's (Popen's process_group, which Python 3.10 lacks);
    and be killed (SIGKILL) with the thread that started it, so that a trial never outlives
    what started it, such as a Ray worker killed with its node or its driver (Linux's
    PR_SET_PDEATHSIG, kept across exec)."""
    def setup() -> None:
        os.setpgid(0, group)
        if _PRCTL is not None:
            _PRCTL(1, signal.SIGKILL)                   # 1: PR_SET_PDEATHSIG
    return setup


def _wait_for_file(path: Path, timeout: float) -> bool:
    """Until a process writes ``path`` (the recorder's signal that it records /clock), or
    the campaign is stopped."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists():
            return True
        if INTERRUPTED.wait(0.05):
            return False
    return False


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process (Linux /proc), or NaN."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, IndexError, ValueError):
        return float('nan')


# [s] A stopped campaign's trials: SIGKILL this long after SIGINT (within the 10 s that
# `docker stop` and most process managers wait after their SIGTERM).
INTERRUPT_GRACE = 5.0


def _stop_group(group: Optional[int], procs: Dict[str, 'subprocess.Popen[bytes]'],
                interrupted: bool = False) -> None:
    """Stop a trial's processes: SIGINT (each node ends between callbacks, the recorder closes
    its bag), and SIGKILL for those still running 10 s later, or ``INTERRUPT_GRACE`` later
    when the campaign was stopped."""
    if group is None:
        return
    steps = ((signal.SIGINT, INTERRUPT_GRACE if interrupted else 10.0), (signal.SIGKILL, 5.0))
    for sig, grace in steps:
        try:
            os.killpg(group, sig)
        except ProcessLookupError:
            return
        end = time.monotonic() + grace
        while time.monotonic() < end and any(p.poll() is None for p in procs.values()):
            time.sleep(0.05)
        if all(p.poll() is not None for p in procs.values()):
            return


def stop_all(at_once: bool = False) -> None:
    """Stop every running trial (their results read 'interrupted'): each trial's own thread
    stops its processes as at a trial's end, with a shorter grace (the bags are closed). At
    once (SIGKILL): the user insisted (a second Ctrl-C while the trials were being stopped)."""
    INTERRUPTED.set()
    if not at_once:
        return
    for group in list(ACTIVE_GROUPS):
        try:
            os.killpg(group, signal.SIGKILL)
        except ProcessLookupError:
            pass
