"""Trials as Ray tasks (``run_trials --ray [ADDRESS]``): a campaign spread over a cluster.

Each trial is one task that reserves ``--cpus-per-trial`` CPUs on whichever node runs it. There
it takes a DDS domain no other trial on that node holds (``domain_lease``), keeps discovery to
localhost, and runs the trial's process group as ``run_trials`` does on one machine. The task
returns the result and the trial's files (logs, events, result); the driver writes them into
its own campaign directory. A bag stays on the worker, named in the result, unless
``--collect-bags``.

Every node needs this project's workspace at the driver's commit, and Ray started from a shell
that sourced ``scripts/env.sh`` (the tasks start ``sim_node`` and the other executables from
PATH, with that environment). A node with other code refuses its trials, since its results
would not be comparable.

This module is imported only with ``--ray``.
"""
from __future__ import annotations

import logging
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import ray

from ros_common.outputs import OutputError, inner_dir, write_file
from studies.progress import read_progress
from studies.trial_process import PROGRESS_FILE, PlanItem, run_leased_trial
from trial_record.result import RESULT_FILE, RunInfo, TrialResult, code_version

# Where a worker keeps its trials' directories: <tmp>/run_trials/<campaign>/trial_NNN.
WORKER_ROOT = 'run_trials'
# Wall seconds between two progress reports of a running trial.
PROGRESS_PERIOD_S = 2.0
# Wall seconds that the driver gives cancelled tasks to stop their process groups.
CANCEL_GRACE_S = 30.0


class ProgressBoard:
    """The running trials' progress as their tasks report it (the driver cannot read the
    progress files on the workers)."""

    def __init__(self) -> None:
        self._reports: Dict[int, Dict[str, Any]] = {}

    def report(self, trial: int, progress: Optional[Dict[str, Any]]) -> None:
        if progress is None:
            self._reports.pop(trial, None)
        else:
            self._reports[trial] = progress

    def snapshot(self) -> Dict[int, Dict[str, Any]]:
        return dict(self._reports)


# The board as a Ray actor (it takes no CPU).
RemoteProgressBoard = ray.remote(num_cpus=0)(ProgressBoard)


def _report_progress(board: Any, trial: int, path: Path, done: threading.Event) -> None:
    """Send the trial's progress file to the board every PROGRESS_PERIOD_S until ``done``."""
    while not done.wait(PROGRESS_PERIOD_S):
        progress = read_progress(path)
        if progress is not None:
            board.report.remote(trial, progress)
    board.report.remote(trial, None)


def _failure(item: PlanItem, message: str, host: str = '') -> TrialResult:
    """The record of a planned trial that did not run."""
    return TrialResult.failure('error', message, item['trial'], item['seed'],
                               item['belt_speed'], RunInfo(wall_time=0.0, node=host))


def run_trial_task(item: PlanItem, campaign: str, options: Dict[str, Any], collect_bags: bool,
                   board: Any = None) -> Tuple[TrialResult, Dict[str, bytes]]:
    """One trial on this node (a Ray task): its result, with where it ran, and its files by
    path within the trial's directory (but its result, which the driver writes)."""
    host = socket.gethostname()
    if shutil.which('sim_node') is None:
        return _failure(item, f'sim_node is not on PATH on {host}: start Ray there from a '
                        'shell that sourced scripts/env.sh', host), {}
    code = code_version()
    if code != options['code']:
        return _failure(item, f'{host} runs code {code}, the driver {options["code"]}: check '
                        'out and build the same commit on every node', host), {}
    work = Path(tempfile.gettempdir()) / WORKER_ROOT / campaign
    trial_dir = work / f'trial_{item["trial"]:03d}'
    done = threading.Event()
    if board is not None:
        threading.Thread(target=_report_progress, daemon=True,
                         args=(board, item['trial'], trial_dir / PROGRESS_FILE, done)).start()
    try:
        result = run_leased_trial(item, work, options)
    finally:
        done.set()
    files = {}
    for path in sorted(trial_dir.rglob('*')):
        relative = path.relative_to(trial_dir)
        if (path.is_file() and (collect_bags or relative.parts[0] != 'bag')
                and str(relative) != RESULT_FILE):
            files[str(relative)] = path.read_bytes()
    result = result.with_run(node=host, ray_node=ray.get_runtime_context().get_node_id(),
                             niceness=os.nice(0))
    if options['record'] and not collect_bags:
        result = result.with_run(bag=f'{host}:{trial_dir / "bag"}')
    else:
        shutil.rmtree(trial_dir, ignore_errors=True)
    return result, files


class RayPool:
    """Trials as tasks on a Ray cluster, as many at a time as its CPUs allow (or ``limit``)."""

    def __init__(self, address: Optional[str], out: Path, options: Dict[str, Any],
                 cpus_per_trial: Optional[float] = None, collect_bags: bool = False,
                 limit: Optional[int] = None) -> None:
        on_term = signal.getsignal(signal.SIGTERM)
        # Ray starts its workers at niceness 15, and a trial's processes would inherit it: on a
        # node with other work they would crawl (a lock-step trial at a few % of a core).
        ray.init(address=address, logging_level=logging.WARNING, log_to_driver=False,
                 configure_logging=True,
                 runtime_env={'env_vars': {'RAY_worker_niceness': '0'}})
        signal.signal(signal.SIGTERM, on_term)   # (ray.init takes SIGTERM: SIGTERM stops a
        #                                          campaign as Ctrl-C does)
        self._out, self._options, self._collect = out, options, collect_bags
        self._cpus = cpus_per_trial or 1.0
        self._task = ray.remote(num_cpus=self._cpus, max_retries=0)(run_trial_task)
        # The campaign's name on the workers: unique per driver run.
        self._campaign = f'{out.resolve().name}-{socket.gethostname()}-{time.time_ns()}'
        self._limit = limit
        self._final_capacity: Optional[int] = None     # once disconnected
        # (An actor handle: Ray's type information does not cover its methods' .remote.)
        self._board: Any = RemoteProgressBoard.remote()
        self._refs: Dict[Any, PlanItem] = {}             # ObjectRef -> plan item
        self.running: Dict[int, float] = {}            # trial -> when it was submitted

    @property
    def capacity(self) -> int:
        """Trials the cluster runs at once now (its CPUs, which may grow or shrink)."""
        if self._final_capacity is not None:
            return self._final_capacity
        slots = int(ray.cluster_resources().get('CPU', 0.0)  # type: ignore[no-untyped-call]
                    // self._cpus)
        return max(1, min(slots, self._limit) if self._limit else slots)

    def describe(self) -> str:
        nodes = [n for n in ray.nodes() if n.get('Alive')]  # type: ignore[no-untyped-call]
        return (f'on a Ray cluster of {len(nodes)} node(s), {self.capacity} at a time '
                f'({self._cpus:g} CPU per trial)')

    def has_room(self) -> bool:
        return len(self._refs) < self.capacity

    def busy(self) -> bool:
        return bool(self._refs)

    def submit(self, item: PlanItem) -> None:
        self.running[item['trial']] = time.monotonic()
        ref = self._task.remote(item, self._campaign, self._options, self._collect,
                                self._board)
        self._refs[ref] = item

    def wait(self, timeout: float) -> Optional[TrialResult]:
        """The next finished trial's result (its files written into the campaign directory),
        or None after ``timeout`` seconds."""
        ready, _ = ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if not ready:
            return None
        item = self._refs.pop(ready[0])
        self.running.pop(item['trial'], None)
        result: TrialResult
        files: Dict[str, bytes]
        try:
            result, files = ray.get(ready[0])
        except ray.exceptions.RayError as exc:        # the task or its node failed
            result, files = _failure(item, f'the Ray task failed: {exc}'.splitlines()[0]), {}
        self._write(item['trial'], result, files)
        return result

    def _write(self, trial: int, result: TrialResult, files: Dict[str, bytes]) -> None:
        trial_dir = self._out / f'trial_{trial:03d}'
        try:
            inner_dir(trial_dir, 'the trial\'s directory')
            for name, data in files.items():
                parts = Path(name).parts
                if not parts or Path(name).is_absolute() or '..' in parts:
                    continue                  # (only files of the trial's own directory)
                where = trial_dir
                for part in parts[:-1]:
                    where = inner_dir(where / part, 'a directory of the trial\'s')
                write_file(where / parts[-1], data)
            result.write(trial_dir / RESULT_FILE)
        except OutputError as exc:
            print(f'[trials] trial {trial}: its files are not written: {exc}', flush=True)

    def progress(self) -> Dict[int, Dict[str, Any]]:
        """The running trials' progress, as their tasks last reported it."""
        try:
            snapshot: Dict[int, Dict[str, Any]] = ray.get(self._board.snapshot.remote(),
                                                          timeout=5.0)
            return snapshot
        except ray.exceptions.RayError:
            return {}

    def stop(self) -> None:
        """Cancel every trial: a running task is interrupted, which stops its process
        group."""
        refs: List[Any] = list(self._refs)
        for ref in refs:
            ray.cancel(ref)
        ray.wait(refs, num_returns=len(refs), timeout=CANCEL_GRACE_S)
        self._refs.clear()
        self.running.clear()

    def close(self) -> None:
        self._final_capacity = self.capacity
        ray.shutdown()

    def drain(self) -> List[TrialResult]:
        """After ``stop``: no results (canceled tasks return none; --resume runs them)."""
        return []
