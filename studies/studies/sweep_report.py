"""A sweep's part of the report: each point's rates with their 95 % Wilson intervals and its
completion time, where the cell starts to fail, and the plots of both against the parameter."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from studies.sweep import RATES, PointSummary, breaking_point, summarise
from trial_record.result import TrialResult

FONT = cv2.FONT_HERSHEY_SIMPLEX
RATE_COLORS = {'identification': (180, 119, 31), 'grasp': (14, 127, 255),
               'handling': (44, 160, 44)}                   # BGR
SERIES_COLORS = ((180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214),
                 (189, 103, 148), (75, 86, 140), (194, 119, 227), (127, 127, 127))


def _label(point: Tuple[Tuple[str, float], ...]) -> str:
    return ', '.join(f'{name} {value:g}' for name, value in point)


def _pct(rate: Tuple[float, float, float]) -> str:
    value, lo, hi = rate
    if not math.isfinite(value):
        return '-'
    return f'{100 * value:.1f} [{100 * lo:.0f}, {100 * hi:.0f}]'


def sweep_lines(trials: Sequence[TrialResult], out_dir: Path, break_below: float
                ) -> List[str]:
    """The sweep's section of report.md (and its plots in ``out_dir``); [] when the trials
    are no sweep."""
    rows = summarise(trials)
    if not rows:
        return []
    names = [name for name, _ in rows[0].point]
    lines = ['## The sweep', '',
             f'{len(rows)} points of {" x ".join(names)}, {rows[0].trials} trials at the first; '
             'the same scenario seeds at every point. Rates in %, with their 95 % Wilson '
             'interval over the materials (grasp: over the attempts); time: the completed '
             'trials\' median, simulated seconds.', '',
             '| point | trials | completed | identification | grasp | handling | time (s) |',
             '|---|---|---|---|---|---|---|']
    for row in rows:
        time = f'{row.median_time:.1f}' if math.isfinite(row.median_time) else '-'
        lines.append(f'| {_label(row.point)} | {row.trials} | {row.completed} | '
                     + ' | '.join(_pct(row.rates[name]) for name in RATES) + f' | {time} |')
    lines += ['', f'Where it starts to fail (the first point with a rate below '
                  f'{100 * break_below:g} %):', '']
    for name in RATES:
        found = breaking_point(rows, name, break_below)
        lines.append(f'- {name}: ' + (f'at {_label(found)}' if found is not None else
                                      f'never, over the {len(rows)} points'))
    lines.append('')
    sweep_plots(rows, out_dir)
    lines += ['![rates over the sweep](sweep_rates.png) '
              '![completion time over the sweep](sweep_times.png)', '']
    return lines


def sweep_plots(rows: Sequence[PointSummary], out_dir: Path) -> None:
    """``sweep_rates.png`` (each rate against the first parameter, with its interval; a grid:
    the handling rate, a line per value of the second) and ``sweep_times.png``."""
    names = [name for name, _ in rows[0].point]
    xs = sorted({row.point[0][1] for row in rows})
    if len(names) == 1:
        rates = {name: [(row.point[0][1], *row.rates[name]) for row in rows] for name in RATES}
        _plot(rates, xs, names[0], 'rate [%]', (0.0, 100.0),
              f'Rates against {names[0]} (95 % Wilson intervals)', out_dir / 'sweep_rates.png',
              scale=100.0, colors=RATE_COLORS)
        times = {'median': [(row.point[0][1], row.median_time, math.nan, math.nan)
                            for row in rows]}
    else:
        second = sorted({row.point[1][1] for row in rows})
        rates = {f'{names[1]} {v:g}': [(row.point[0][1], *row.rates['handling'])
                                       for row in rows if row.point[1][1] == v] for v in second}
        _plot(rates, xs, names[0], 'handling [%]', (0.0, 100.0),
              f'Handling against {names[0]}, a line per {names[1]}',
              out_dir / 'sweep_rates.png', scale=100.0)
        times = {f'{names[1]} {v:g}': [(row.point[0][1], row.median_time, math.nan, math.nan)
                                       for row in rows if row.point[1][1] == v]
                 for v in second}
    finite = [t[1] for series in times.values() for t in series if math.isfinite(t[1])]
    span = (math.floor(min(finite)) - 1.0, math.ceil(max(finite)) + 1.0) if finite else (0, 1)
    _plot(times, xs, names[0], 'completion time [s]', span,
          f'Completion time (median of the completed trials) against {names[0]}',
          out_dir / 'sweep_times.png')


def _plot(series: Dict[str, List[Tuple[float, float, float, float]]], xs: Sequence[float],
          xlabel: str, ylabel: str, span: Tuple[float, float], title: str, out: Path,
          scale: float = 1.0, colors: Optional[Dict[str, Tuple[int, int, int]]] = None
          ) -> None:
    """Lines of (x, value, low, high) points, each with its interval as a bar (nan: none)."""
    colors = colors or {}
    img = np.full((520, 900, 3), 255, np.uint8)
    left, top, w, h = 80, 50, 640, 380
    cv2.putText(img, title, (left, 30), FONT, 0.55, (0, 0, 0), 1)
    x0, x1 = (xs[0] - 0.5, xs[0] + 0.5) if len(xs) == 1 else (xs[0], xs[-1])
    if not x1 - x0 > 0.0:                 # (values too close to tell apart in a float)
        x0, x1 = x0 - 0.5, x0 + 0.5
    pad = (x1 - x0) * 0.05
    if not span[1] - span[0] > 0.0:
        span = (span[0] - 1.0, span[0] + 1.0)

    def px(x: float) -> int:
        return int(left + (x - x0 + pad) / (x1 - x0 + 2 * pad) * w)

    def py(y: float) -> int:
        return int(top + h - (y * scale - span[0]) / (span[1] - span[0]) * h)
    for k in range(6):
        value = span[0] + (span[1] - span[0]) * k / 5
        y = int(top + h - h * k / 5)
        cv2.line(img, (left, y), (left + w, y), (230, 230, 230), 1)
        cv2.putText(img, f'{value:.0f}', (left - 45, y + 5), FONT, 0.45, (0, 0, 0), 1)
    for x in xs:
        cv2.putText(img, f'{x:g}', (px(x) - 14, top + h + 20), FONT, 0.42, (0, 0, 0), 1)
    for i, (name, points) in enumerate(series.items()):
        color = colors.get(name, SERIES_COLORS[i % len(SERIES_COLORS)])
        shown = [(x, v, lo, hi) for x, v, lo, hi in points if math.isfinite(v)]
        for (xa, va, _, _), (xb, vb, _, _) in zip(shown, shown[1:]):
            cv2.line(img, (px(xa), py(va)), (px(xb), py(vb)), color, 2, cv2.LINE_AA)
        for x, v, lo, hi in shown:
            if math.isfinite(lo) and math.isfinite(hi):
                cv2.line(img, (px(x), py(lo)), (px(x), py(hi)), color, 1)
                for end in (lo, hi):
                    cv2.line(img, (px(x) - 4, py(end)), (px(x) + 4, py(end)), color, 1)
            cv2.circle(img, (px(x), py(v)), 4, color, -1, cv2.LINE_AA)
        cv2.rectangle(img, (left + w + 15, top + 10 + 22 * i), (left + w + 30, top + 22 + 22 * i),
                      color, -1)
        cv2.putText(img, name, (left + w + 36, top + 21 + 22 * i), FONT, 0.42, (0, 0, 0), 1)
    cv2.rectangle(img, (left, top), (left + w, top + h), (0, 0, 0), 1)
    cv2.putText(img, xlabel, (left + w // 2 - 60, top + h + 45), FONT, 0.5, (0, 0, 0), 1)
    cv2.putText(img, ylabel, (5, top - 12), FONT, 0.45, (0, 0, 0), 1)
    if not cv2.imwrite(str(out), img):
        raise OSError(f'cannot write {out}')
