"""Where a campaign's trials run: the ``Pool`` a campaign submits its trials to (``LocalPool``:
process groups on this machine, some at a time; ray_pool.RayPool: tasks on a Ray cluster), and
the running trials' progress and the campaign's ETA, from their progress files."""
from __future__ import annotations

import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Protocol, Tuple

from studies.progress import TrialProgress, eta_seconds, read_progress
from studies.trial_process import PROGRESS_FILE, PlanItem, run_leased_trial, stop_all
from trial_record.result import TrialResult


class Pool(Protocol):
    """Where a campaign's trials run (``LocalPool``; ``trials_ray.RayPool``): trials are
    submitted while it has room, and their results taken as they finish."""

    running: Dict[int, float]       # trial -> when it started (monotonic)

    @property
    def capacity(self) -> int:
        """Trials it runs at once."""

    def describe(self) -> str: ...

    def has_room(self) -> bool: ...

    def busy(self) -> bool: ...

    def submit(self, item: PlanItem) -> None: ...

    def wait(self, timeout: float) -> Optional[TrialResult]:
        """The next finished trial's result, or None after ``timeout`` seconds."""

    def progress(self) -> Mapping[int, Optional[Dict[str, Any]]]:
        """The running trials' progress, by trial."""

    def stop(self) -> None:
        """Stop the running trials (soon: a user stopped the campaign)."""

    def close(self) -> None: ...

    def drain(self) -> List[TrialResult]:
        """After ``close``: the results of the trials that were running, now ended."""


class LocalPool:
    """Trials as process groups on this machine, ``parallel`` at a time."""

    def __init__(self, parallel: int, out: Path, options: Dict[str, Any]) -> None:
        self.capacity, self._out, self._options = parallel, out, options
        self._pool = ThreadPoolExecutor(parallel)
        self._futures: Dict['Future[TrialResult]', PlanItem] = {}
        self.running: Dict[int, float] = {}          # trial -> when it started (monotonic)

    def describe(self) -> str:
        return f'{self.capacity} at a time'

    def has_room(self) -> bool:
        return len(self._futures) < self.capacity

    def busy(self) -> bool:
        return bool(self._futures)

    def submit(self, item: PlanItem) -> None:
        self.running[item['trial']] = time.monotonic()
        self._futures[self._pool.submit(run_leased_trial, item, self._out,
                                        self._options)] = item

    def wait(self, timeout: float) -> Optional[TrialResult]:
        """The next finished trial's result, or None after ``timeout`` seconds."""
        finished, _ = wait(self._futures, timeout=timeout, return_when=FIRST_COMPLETED)
        if not finished:
            return None
        done = finished.pop()
        item = self._futures.pop(done)
        self.running.pop(item['trial'], None)
        return done.result()

    def progress(self) -> Dict[int, Optional[Dict[str, Any]]]:
        """The running trials' progress files, by trial (None: none yet)."""
        return {trial: read_progress(self._out / f'trial_{trial:03d}' / PROGRESS_FILE)
                for trial in self.running}

    def stop(self) -> None:
        """Stop the running trials (their results read 'interrupted'; their bags closed)."""
        stop_all()

    def close(self) -> None:
        self._pool.shutdown(wait=True)

    def drain(self) -> List[TrialResult]:
        """After ``close``: the results of the trials that were running, now ended."""
        out = []
        for future in list(self._futures):
            if future.done() and not future.cancelled() and future.exception() is None:
                out.append(future.result())
        self._futures.clear()
        return out


def campaign_progress(pool: Pool, results: List[TrialResult], pending: int
              ) -> Tuple[List[TrialProgress], Optional[float]]:
    """Every running trial's simulated time and deliveries, and the campaign's ETA."""
    now, states = time.monotonic(), []
    reports = pool.progress()
    for trial, since in sorted(pool.running.items()):
        p = reports.get(trial) or {}
        states.append(TrialProgress(trial, float(p.get('sim_time', 0.0)),
                                    int(p.get('delivered', 0)), int(p.get('total', 0)),
                                    now - since, p.get('loader', '-'), p.get('transport', '-')))
    ok = [r for r in results if r.status == 'completed']
    eta = eta_seconds(states, [r.run.wall_time for r in results],
                      [r.completion_time for r in ok], pending, pool.capacity)
    return states, eta
