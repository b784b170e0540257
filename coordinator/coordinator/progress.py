"""Live progress of a trial campaign: what each running trial has done, and an ETA (no ROS).

The coordinator writes its progress (simulated time, materials delivered) to a small JSON file
once per simulated second; the trial runner reads those files and prints one line now and then,
so that a user never waits minutes in silence.
"""
from __future__ import annotations

import json
import os
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

# Before any trial has finished, a trial is taken to need this much simulated time [s]
# (about the median completion of the current schedule, docs/trials/current); afterwards the
# median of the finished ones.
TYPICAL_COMPLETION_S = 60.0


@dataclass(frozen=True)
class TrialProgress:
    trial: int
    sim_time: float           # simulated seconds since the run started
    delivered: int
    total: int
    wall_time: float          # wall seconds since the trial's processes started
    loader: str = ''
    transport: str = ''


def write_progress(path: Path, **fields) -> None:
    """Atomically (a reader never sees half a file)."""
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text(json.dumps(fields))
    os.replace(tmp, path)


def read_progress(path: Path) -> Optional[Dict]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def eta_seconds(running: Sequence[TrialProgress], finished_walls: Sequence[float],
                finished_sims: Sequence[float], pending: int, parallel: int) -> Optional[float]:
    """Wall seconds until the campaign ends, or None before anything can be estimated.

    A running trial's remainder comes from its own pace (simulated over wall seconds) and the
    simulated time a trial needs; a pending trial costs the mean wall time of a finished one
    (or of a running one's projection), ``parallel`` at a time.
    """
    need = statistics.median(finished_sims) if finished_sims else TYPICAL_COMPLETION_S
    remaining, projected = [], []
    for p in running:
        if p.sim_time <= 0.0 or p.wall_time <= 0.0:
            continue
        pace = p.sim_time / p.wall_time
        remaining.append(max(0.0, need - p.sim_time) / pace)
        projected.append(need / pace)
    per_trial = (statistics.mean(finished_walls) if finished_walls else
                 statistics.mean(projected) if projected else None)
    if per_trial is None:
        return None
    busy = max(remaining) if remaining else 0.0
    return busy + per_trial * pending / max(1, parallel)


def format_duration(seconds: Optional[float]) -> str:
    if seconds is None:
        return '?'
    seconds = int(round(seconds))
    if seconds >= 3600:
        return f'{seconds // 3600} h {seconds % 3600 // 60:02d} min'
    if seconds >= 60:
        return f'{seconds // 60} min {seconds % 60:02d} s'
    return f'{seconds} s'


def progress_line(done: int, planned: int, running: List[TrialProgress],
                  eta: Optional[float]) -> str:
    trials = '; '.join(f'trial {p.trial}: {p.sim_time:.0f} s sim, {p.delivered}/{p.total} '
                       f'delivered ({p.loader}/{p.transport})' for p in running)
    return (f'[trials] {done}/{planned} done; ' + (trials or 'starting')
            + f'; ETA {format_duration(eta)}')
