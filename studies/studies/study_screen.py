"""A study's screening: which factors matter, for each response.

The design is SALib's Latin hypercube over all factors (``points`` settings, each factor's
range cut into as many strata), each setting run ``replicates`` times with scenario seeds of its
own. For each response, two measures rank the factors:

- the **main effect**: the change in the response from a factor's low end to its high end, all
  others held, from a least-squares fit of the response on the factors (scaled to 0..1) over the
  design, with its 95 % interval (Student's t); the factors are ranked by its size;
- SALib's **RBD-FAST first-order index**: the share of the response's variance that the factor
  alone explains, with its 95 % bootstrap interval (it sees effects that are not straight
  lines, which the main effect would miss).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

import numpy as np

from ros_common.outputs import save_figure
from studies.plan import trial_plan
from studies.study_file import Study, response_of
from studies.trial_process import PlanItem
from trial_record.result import TrialResult


@dataclass(frozen=True)
class Effect:
    factor: str
    effect: float                 # low end -> high end
    low: float                    # its 95 % interval
    high: float
    s1: float                     # RBD-FAST first-order index (nan: too few points)
    s1_conf: float


def design(study: Study) -> np.ndarray:
    """The Latin hypercube's settings (points x factors), from the study's seed."""
    from SALib.sample import latin
    assert study.screening is not None
    x = latin.sample(_problem(study), study.screening.points, seed=study.seed)
    for j, f in enumerate(study.factors):
        x[:, j] = [f.snap(v) for v in x[:, j]]
    return np.asarray(x)


def _problem(study: Study) -> Dict[str, Any]:
    return {'num_vars': len(study.factors), 'names': [f.name for f in study.factors],
            'bounds': [[f.low, f.high] for f in study.factors]}


def plan(study: Study) -> List[PlanItem]:
    """Every trial of the screening: setting i's k-th replicate is trial i * replicates + k,
    each with a scenario seed of its own (and a belt speed drawn from the study's range unless
    the belt speed is a factor)."""
    assert study.screening is not None
    rep = study.screening.replicates
    x = design(study)
    seeds = trial_plan(len(x) * rep, 0, study.seed, study.belt_speed)
    items = []
    for i, row in enumerate(x):
        values = {f.name: float(row[j]) for j, f in enumerate(study.factors)}
        for k in range(rep):
            base = seeds[i * rep + k]
            items.append(PlanItem(trial=base['trial'], seed=base['seed'],
                                  belt_speed=values.get('belt_speed', base['belt_speed']),
                                  parameters=values))
    return items


def responses(study: Study, items: Sequence[PlanItem], results: Sequence[TrialResult]
              ) -> Tuple[np.ndarray, Dict[str, np.ndarray]]:
    """The settings that ran (rows of factors) and each response at each, over its
    replicates; a trial that did not run (an error) leaves its setting out."""
    by_trial = {r.trial: r for r in results if r.ran}
    rows: Dict[Tuple[float, ...], List[TrialResult]] = {}
    for item in items:
        key = tuple(item['parameters'][f.name] for f in study.factors)
        if item['trial'] in by_trial:
            rows.setdefault(key, []).append(by_trial[item['trial']])
    x = np.array(list(rows), dtype=float).reshape(-1, len(study.factors))
    ys = {}
    for name in study.responses:
        values = []
        for trials in rows.values():
            s = sum(response_of(r, name)[0] for r in trials)
            n = sum(response_of(r, name)[1] for r in trials)
            values.append(s / n if n else math.nan)
        ys[name] = np.array(values)
    return x, ys


def effects(study: Study, x: np.ndarray, y: np.ndarray) -> List[Effect]:
    """Each factor's main effect on one response, and its RBD-FAST index: largest first."""
    from scipy import stats
    keep = np.isfinite(y)
    x, y = x[keep], y[keep]
    k = len(study.factors)
    lo = np.array([f.low for f in study.factors])
    span = np.array([f.high - f.low for f in study.factors])
    a = np.column_stack([np.ones(len(x)), (x - lo) / span])
    dof = len(x) - a.shape[1]
    if dof < 1:
        return []
    # (Centred: a response that does not vary fits to exact zeros, not to rounding noise
    # whose interval leaves out zero.)
    y = y - float(np.mean(y))
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ coef
    sigma2 = float(resid @ resid) / dof
    cov = sigma2 * np.linalg.pinv(a.T @ a)
    t = float(stats.t.ppf(0.975, dof))
    s1, s1_conf = _rbd_fast(study, x, y)
    half = [t * math.sqrt(max(0.0, float(cov[j + 1, j + 1]))) for j in range(k)]
    out = [Effect(f.name, float(coef[j + 1]), float(coef[j + 1]) - half[j],
                  float(coef[j + 1]) + half[j], s1[j], s1_conf[j])
           for j, f in enumerate(study.factors)]
    assert len(out) == k
    return sorted(out, key=lambda e: -abs(e.effect))


def _rbd_fast(study: Study, x: np.ndarray, y: np.ndarray) -> Tuple[List[float], List[float]]:
    """SALib's RBD-FAST first-order indices and their 95 % intervals (nan with too few
    settings, or a response that does not vary)."""
    nan = [math.nan] * len(study.factors)
    if len(x) < 16 or float(np.std(y)) == 0.0:
        return nan, nan
    from SALib.analyze import rbd_fast
    m = max(2, min(10, len(x) // 8))
    try:
        res = rbd_fast.analyze(_problem(study), x, y, M=m, num_resamples=200, seed=study.seed)
    except (ValueError, ZeroDivisionError, FloatingPointError):
        return nan, nan
    return ([float(v) for v in res['S1']], [float(v) for v in res['S1_conf']])


def ranking_lines(name: str, ranked: Sequence[Effect]) -> List[str]:
    """The report's table of one response."""
    lines = [f'**{name}**', '',
             '| rank | factor | main effect (low to high) | 95 % interval | RBD-FAST S1 |',
             '|---|---|---|---|---|']
    for i, e in enumerate(ranked, 1):
        s1 = (f'{e.s1:.2f} ± {e.s1_conf:.2f}' if math.isfinite(e.s1) else '-')
        lines.append(f'| {i} | {e.factor} | {e.effect:+.4g} | [{e.low:+.4g}, {e.high:+.4g}] '
                     f'| {s1} |')
    if len(ranked) >= 2:
        lines += ['', _how_sure(ranked)]
    return lines + ['']


def _how_sure(ranked: Sequence[Effect]) -> str:
    """Whether the first factors stand apart from the rest (their intervals)."""
    def clear(e: Effect) -> bool:          # (its interval excludes no effect)
        return e.low > 0.0 or e.high < 0.0
    strong = [e.factor for e in ranked if clear(e)]
    if not strong:
        return ('No factor\'s effect is clear of zero at 95 %: the design cannot tell them '
                'apart (more points or replicates).')
    first, second = ranked[0], ranked[1]
    apart = min(abs(first.low), abs(first.high)) > max(abs(second.low), abs(second.high))
    return (f'Effects clear of zero at 95 %: {", ".join(strong)}. The first '
            + ('stands apart from the second (their intervals do not overlap).' if apart else
               'and the second overlap: their order may change with another design.'))


def plot(study: Study, ranked: Dict[str, List[Effect]], path: Path) -> None:
    """One panel per response: each factor's main effect as a bar with its 95 % interval,
    largest on top (matplotlib)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    names = [n for n in ranked if ranked[n]]
    if not names:
        return
    fig, axes = plt.subplots(1, len(names), figsize=(5.0 * len(names), 0.6 * len(
        study.factors) + 1.6), squeeze=False)
    for ax, name in zip(axes[0], names):
        effects_ = list(reversed(ranked[name]))
        ys = range(len(effects_))
        values = [e.effect for e in effects_]
        err = [[e.effect - e.low for e in effects_], [e.high - e.effect for e in effects_]]
        colours = ['tab:red' if e.high < 0 else 'tab:green' if e.low > 0 else 'tab:gray'
                   for e in effects_]
        ax.barh(list(ys), values, xerr=err, color=colours, capsize=3)
        ax.set_yticks(list(ys), [e.factor.split('.')[-1] if len(e.factor) > 24 else e.factor
                                 for e in effects_], fontsize=8)
        ax.axvline(0.0, color='black', linewidth=0.8)
        ax.set_title(f'{name}: change from low to high', fontsize=9)
    fig.suptitle(study.question or 'screening', fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
