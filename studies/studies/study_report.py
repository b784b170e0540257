"""A search's part of ``study.md``: the answer and how sure it is, every setting tried with its
trials and its verdict, and a plot of them (matplotlib)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import List

from ros_common.outputs import save_figure
from studies.study_file import Study
from studies.study_search import SearchAnswer, Setting


def _values(s: Setting) -> str:
    return ', '.join(f'{k} {v:g}' for k, v in s.values.items())


def search_lines(study: Study, answer: SearchAnswer) -> List[str]:
    spec = study.search
    assert spec is not None
    c = spec.constraint
    lines = ['## The answer', '', answer.summary, '']
    if c is not None:
        lines += [f'A setting runs the study\'s scenario seeds in order, {spec.first_trials} '
                  f'trials first and then a batch at a time, until the constraint is decided as '
                  f'{spec.trials_per_setting} trials would decide it: met once the '
                  f'{c.response} rate\'s {c.confidence:.0%} Wilson lower bound (over the '
                  f'materials) reaches {c.at_least:g}; failed once it could not, even if every '
                  'trial still allowed came out perfect.', '']
    best = answer.best
    if best is not None:
        trials = ', '.join(f'`trial_{r.trial:03d}`' for r in best.results
                           if r.trial is not None)
        lines += [f'The trials behind the answer: {trials}.', '']
    if len(study.factors) == 1 and best is not None and c is not None:
        name = study.factors[0].name
        sign = 1.0 if spec.maximise else -1.0
        against = [s for s in answer.settings if s.feasible is False
                   and sign * (s.values[name] - best.values[name]) < 0]
        if against:
            lines += [f'Not monotone: {", ".join(_values(s) for s in against)} failed the '
                      f'constraint on the near side of the answer; the halving assumes a '
                      f'setting beyond a failed one fails too, which the data here do not '
                      'promise.', '']
    lines += ['## The settings tried', '',
              '| setting | values | trials | ' + (f'{c.response} | verdict |' if c else '')
              + f' {spec.objective} |', '|---|---|---|' + ('---|---|' if c else '') + '---|']
    for s in answer.settings:
        row = f'| {s.index} | {_values(s)} | {len(s.results)} | '
        if c is not None:
            rate = s.mean(c.response)
            row += (f'{rate:.1%} | ' if math.isfinite(rate) else '- | ')
            row += ('met' if s.feasible else 'failed') + f': {s.how} | '
        value = s.values.get(spec.objective, s.mean(spec.objective))
        lines.append(row + f'{value:.4g} |')
    lines += ['', '![the settings tried](study_search.png)', '']
    return lines


def search_plot(study: Study, answer: SearchAnswer, path: Path) -> None:
    """The constraint's rate (with its interval) at each setting tried, against the first
    factor: green met, red failed; the answer marked. Without a constraint, the objective."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    spec = study.search
    assert spec is not None
    if not answer.settings:
        return
    c = spec.constraint
    name = study.factors[0].name
    fig, ax = plt.subplots(figsize=(8.0, 4.6))
    for s in answer.settings:
        x = s.values[name]
        if c is not None:
            low, high = s.bounds(c)
            rate = s.mean(c.response)
            if not math.isfinite(rate):
                continue
            colour = 'tab:green' if s.feasible else 'tab:red'
            ax.errorbar([x], [rate], yerr=[[max(0.0, rate - low)], [max(0.0, high - rate)]],
                        fmt='o', color=colour, capsize=3)
            ax.annotate(f'{s.index}: {len(s.results)}', (x, high), fontsize=7,
                        textcoords='offset points', xytext=(0, 4), ha='center')
        else:
            ax.plot([x], [s.mean(spec.objective)], 'o', color='tab:blue')
    if c is not None:
        ax.axhline(c.at_least, color='black', linestyle='--', linewidth=0.8,
                   label=f'the bound: lower bound at least {c.at_least:g}')
        ax.plot([], [], 'o', color='tab:green', label='meets it')
        ax.plot([], [], 'o', color='tab:red', label=f'fails it (its lower bound cannot reach '
                f'{c.at_least:g} in {spec.trials_per_setting} trials)')
        ax.legend(fontsize=7, loc='upper center', bbox_to_anchor=(0.5, -0.16), ncol=3,
                  frameon=False)
        ax.set_ylabel(f'{c.response} rate ({c.confidence:.0%} Wilson interval)')
    else:
        ax.set_ylabel(spec.objective)
    if answer.best is not None:
        ax.axvline(answer.best.values[name], color='tab:green', linewidth=0.8)
    ax.set_xlabel(f'{name} (each point: setting: trials)')
    ax.set_title((study.question or 'search')[:90], fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
