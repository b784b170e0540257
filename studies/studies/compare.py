"""compare_runs A B: what differs between two runs (two trials) or two campaigns.

Two trials: their Table-2 figures side by side, the first event where they part, both
timelines on one time axis, and the youBot's two paths over one map. Two campaigns: each rate
with its 95 % Wilson interval, the difference and whether it is significant (a two-sided
two-proportion z-test over the materials), and the completion times (medians, Mann-Whitney U).
Written to ``--out``/comparison.md with its plots; the summary printed.

    compare_runs runs/pipeline-A runs/rerun-B [--out DIR]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ros_common.outputs import OutputError, check_output_dir, staged_dir
from studies.campaign import trial_results
from studies.recorded import RecordError, load_trial
from studies.rerun import figures, first_parting
from studies.sweep import RATES, wilson
from trial_record.result import TrialResult

SIGNIFICANT = 0.05


def load_runs(path: Path) -> List[TrialResult]:
    """A trial (its result, its directory, a run directory with one trial, its bag) or a
    campaign (a directory of trials); ValueError saying why not."""
    if path.is_dir() and len(list(path.glob('trial_*/result.json'))) > 1:
        results, problems = trial_results(path)
        if problems:
            more = f' (and {len(problems) - 1} more)' if len(problems) > 1 else ''
            raise ValueError(f'{problems[0]}{more}')
        return results
    try:
        return [load_trial(path)[0]]
    except RecordError as exc:
        raise ValueError(str(exc)) from None


def two_proportions(s1: int, n1: int, s2: int, n2: int) -> float:
    """The two-sided p-value that two proportions are the same (pooled z-test); nan if a
    sample is empty, 1 when both are the same extreme."""
    if n1 <= 0 or n2 <= 0:
        return math.nan
    pooled = (s1 + s2) / (n1 + n2)
    se = math.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    if se == 0.0:
        return 1.0
    z = (s1 / n1 - s2 / n2) / se
    return math.erfc(abs(z) / math.sqrt(2.0))


def mann_whitney(a: Sequence[float], b: Sequence[float]) -> float:
    """The two-sided p-value that two samples come from one distribution (Mann-Whitney U,
    normal approximation with ties' correction); nan for an empty sample."""
    if not a or not b:
        return math.nan
    values = np.concatenate([np.asarray(a, float), np.asarray(b, float)])
    order = values.argsort(kind='mergesort')
    ranks = np.empty(len(values))
    sorted_values = values[order]
    i = 0
    while i < len(values):
        j = i
        while j + 1 < len(values) and sorted_values[j + 1] == sorted_values[i]:
            j += 1
        ranks[order[i:j + 1]] = (i + j) / 2 + 1
        i = j + 1
    n1, n2 = len(a), len(b)
    u = float(ranks[:n1].sum()) - n1 * (n1 + 1) / 2
    _, counts = np.unique(values, return_counts=True)
    n = n1 + n2
    variance = n1 * n2 / 12 * ((n + 1) - float((counts ** 3 - counts).sum()) / (n * (n - 1)))
    if variance <= 0.0:
        return 1.0
    z = (u - n1 * n2 / 2) / math.sqrt(variance)
    return math.erfc(abs(z) / math.sqrt(2.0))


def compare_trials(a: TrialResult, b: TrialResult, out: Path, names: Tuple[str, str]
                   ) -> List[str]:
    """The comparison of two runs (comparison.md's lines; its plots into ``out``)."""
    lines = ['# Two runs compared', '', f'A: {names[0]}  ', f'B: {names[1]}', '',
             '| | A | B |', '|---|---|---|']
    lines += [f'| {label} | {x} | {y} |' for label, x, y in figures(a, b)]
    differ = b.differences(a)
    lines += ['', 'They differ in: ' + (', '.join(differ) if differ else
                                        'nothing (the same run)') + '.', '']
    parting = first_parting(a, b)
    if parting:
        named = parting.replace('the first run', 'A').replace('the second run', 'B')
        lines += [f'Where they part: {named}.', '']
    _trial_plots(a, b, out)
    lines += ['![both timelines](timelines.png)', '', '![both paths](paths.png)', '']
    return lines


def _trial_plots(a: TrialResult, b: TrialResult, out: Path) -> None:
    from recording.plot import plot_paths
    from studies.report import cell_shapes, timeline_image, write_png
    ends = [t.completion_time for t in (a, b) if math.isfinite(t.completion_time)]
    end = max(ends) if ends else max(
        [float(e[0]) for t in (a, b) for e in t.events] or [1.0])
    write_png(np.vstack([timeline_image(a, end, f'A: {_describe(a)}'),
                         timeline_image(b, end, f'B: {_describe(b)}')]), out / 'timelines.png')
    plot_paths({'A': np.asarray(a.youbot_path or np.zeros((0, 2))),
                'B': np.asarray(b.youbot_path or np.zeros((0, 2)))},
               out / 'paths.png', "The youBot's paths, A and B",
               shapes=cell_shapes(data=a.scenario.get('world_data')))


def _describe(t: TrialResult) -> str:
    done = (f'{t.completion_time:.1f} s' if math.isfinite(t.completion_time) else '-')
    return (f'trial {t.trial}, seed {t.scenario_seed}, belt {t.belt_speed:.3f} m/s, '
            f'{t.status} {done}')


def compare_campaigns(a: Sequence[TrialResult], b: Sequence[TrialResult],
                      names: Tuple[str, str]) -> List[str]:
    """The comparison of two campaigns (comparison.md's lines)."""
    lines = ['# Two campaigns compared', '', f'A: {names[0]} ({len(a)} trials)  ',
             f'B: {names[1]} ({len(b)} trials)', '',
             'Rates in %, with their 95 % Wilson interval; p: two-sided two-proportion '
             f'z-test; significant below {SIGNIFICANT}.', '',
             '| | A | B | B - A | p | |', '|---|---|---|---|---|---|']
    for name, counts in RATES.items():
        s1, n1 = (sum(counts(r)[i] for r in a) for i in (0, 1))
        s2, n2 = (sum(counts(r)[i] for r in b) for i in (0, 1))
        p = two_proportions(s1, n1, s2, n2)
        ra, rb = (s1 / n1 if n1 else math.nan), (s2 / n2 if n2 else math.nan)
        lines.append(f'| {name} | {_pct(ra, *wilson(s1, n1))} | {_pct(rb, *wilson(s2, n2))} | '
                     f'{100 * (rb - ra):+.1f} | {p:.3g} | '
                     f'{"significant" if p < SIGNIFICANT else ""} |')
    ta, tb = ([r.completion_time for r in rs if r.status == 'completed'
               and math.isfinite(r.completion_time)] for rs in (a, b))
    p = mann_whitney(ta, tb)
    ma, mb = (float(np.median(t)) if t else math.nan for t in (ta, tb))
    lines.append(f'| completion time (s, median) | {ma:.1f} | {mb:.1f} | {mb - ma:+.1f} | '
                 f'{p:.3g} (Mann-Whitney) | {"significant" if p < SIGNIFICANT else ""} |')
    completed = [sum(r.status == 'completed' for r in rs) for rs in (a, b)]
    lines += ['', f'Completed runs: A {completed[0]} of {len(a)}, B {completed[1]} of '
              f'{len(b)}.', '']
    return lines


def _pct(value: float, lo: float, hi: float) -> str:
    if not math.isfinite(value):
        return '-'
    return f'{100 * value:.1f} [{100 * lo:.0f}, {100 * hi:.0f}]'


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='compare_runs', description=__doc__.splitlines()[0])
    parser.add_argument('a', type=Path, help='a run (result.json, trial or run directory) or a '
                                             'campaign directory')
    parser.add_argument('b', type=Path, help='the other, of the same kind')
    parser.add_argument('--out', type=Path, default=None,
                        help='where comparison.md and its plots go (runs/compare-<time>)')
    args = parser.parse_args(argv)
    out = args.out or Path('runs') / time.strftime('compare-%Y%m%d-%H%M%S')
    try:
        check_output_dir(out, '--out')                 # (before any work)
        a, b = load_runs(args.a), load_runs(args.b)
        if (len(a) == 1) != (len(b) == 1):
            raise ValueError('compare a run with a run, or a campaign with a campaign '
                             f'({args.a}: {len(a)} trials, {args.b}: {len(b)})')
    except ValueError as exc:                  # (OutputError and RecordError are ValueErrors)
        print(f'compare_runs: error: {exc}', file=sys.stderr)
        return 2
    names = (str(args.a), str(args.b))
    try:
        with staged_dir(out, '--out', last='comparison.md') as stage:
            lines = (compare_trials(a[0], b[0], stage, names) if len(a) == 1
                     else compare_campaigns(a, b, names))
            (stage / 'comparison.md').write_text('\n'.join(lines))
    except (OutputError, OSError) as exc:
        print(f'compare_runs: error: {exc}; nothing written to {out}', file=sys.stderr)
        return 2
    print('\n'.join(line for line in lines if not line.startswith('![')))
    print(f'[compare_runs] {out / "comparison.md"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
