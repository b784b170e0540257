"""Live progress of a trial campaign: what each running trial has done, and an ETA (no ROS).

The coordinator writes its progress (simulated time, materials delivered) to a small JSON file
once per simulated second; the trial runner reads those files and prints one line now and then,
so that a user never waits minutes in silence.
"""
from __future__ import annotations

import math
import shutil
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from trial_record.records import (
    MAX_COUNT,
    MAX_SIM_TIME_S,
    Fields,
    RecordError,
    parse_json,
    read_text,
)
from trial_record.result import TrialResult

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


def read_progress(path: Path) -> Optional[Dict[str, Any]]:
    """A running trial's progress, its fields typed (None: none yet, or not a progress file:
    a campaign's line goes on without it)."""
    try:
        f = Fields(parse_json(read_text(path, 'a progress file', 1 << 16), str(path)), str(path))
        out: Dict[str, Any] = {}
        for key in ('sim_time', 'delivered', 'total', 'loader', 'transport', 'status'):
            if not f.has(key):
                continue
            out[key] = (f.number(key, 0.0, MAX_SIM_TIME_S) if key == 'sim_time' else
                        f.integer(key, 0, MAX_COUNT) if key in ('delivered', 'total') else
                        f.text(key, limit=40))
        return out
    except RecordError:
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


def running_figures(results: Sequence[TrialResult], short: bool = False) -> str:
    """The campaign's Table-2 figures so far: failures, median completion time, and the
    identification, grasp and handling rates over the finished trials (``short``: for a
    terminal's line)."""
    scored = [r for r in results if math.isfinite(r.identification_rate)]
    failed = sum(1 for r in results if r.status != 'completed')
    done = [r.completion_time for r in results if r.status == 'completed']
    parts = [f'{failed} failed' if short else f'{failed} not completed']
    if done:
        parts.append(f'median {statistics.median(done):.1f} s')
    if scored:
        rates = [100 * statistics.mean(getattr(r, k) for r in scored) for k in (
            'identification_rate', 'grasp_success_rate', 'handling_success_rate')]
        parts.append(('ident {:.0f}% grasp {:.0f}% handling {:.0f}%' if short else
                      'identification {:.1f} %, grasp {:.1f} %, handling {:.1f} %'
                      ).format(*rates))
    return '; '.join(parts)


class CampaignBar:
    """A live progress bar of a campaign on a terminal (tqdm): trials done of the plan, the
    running trials' simulated time, failures so far, the running Table-2 figures, and the ETA
    from the trials' own pace (tqdm's, from the finished count alone, would read hours for a
    first trial that is nearly done)."""

    def __init__(self, total: int, done: int, stream: Any) -> None:
        from tqdm import tqdm  # (only for a terminal: logs get lines)
        # The terminal's size at the start (one that reports none: 120 x 24; tqdm hides a bar
        # below a terminal's last line, and a size of 0 lines would hide it).
        size = shutil.get_terminal_size((120, 24))
        self._bar = tqdm(total=total, initial=done, file=stream, unit='trial',
                         ncols=size.columns, nrows=size.lines,
                         bar_format='{desc} {bar:12} {n_fmt}/{total_fmt}{postfix}')
        self._bar.set_description_str('[trials]')
        self._stream = stream

    def update(self, results: Sequence[TrialResult], running: Sequence[TrialProgress],
               eta: Optional[float], finished: int = 0) -> None:
        # The ETA first, the running trials last (a narrow terminal cuts the end off).
        trials = ', '.join(f'#{p.trial} {p.sim_time:.0f} s' for p in running)
        self._bar.set_postfix_str(f'ETA {format_duration(eta)}; '
                                  f'{running_figures(results, short=True)}; {trials or "-"}',
                                  refresh=False)
        self._bar.update(finished)

    def write(self, line: str) -> None:
        """A line above the bar (a finished trial)."""
        self._bar.write(line, file=self._stream)

    def close(self) -> None:
        self._bar.close()
