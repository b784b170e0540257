"""``run_trials --study FILE``: a study's trials run on a campaign's pool (two at a time here,
or a Ray cluster), each a normal trial directory, and its answer written up.

A study's directory holds the study file as given (``study.yaml``), what it is
(``study.json``: its hash and the code), its trials (``trial_NNN``), ``trials.csv`` and, at the
end, ``study.md`` with its plot. ``--resume DIR`` runs the study again from the start, taking
every trial whose result is there (same seed, belt speed and setting, made by the same code)
instead of running it: the search, seeded, proposes the same settings in the same order, so it
goes on where it stopped.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from studies.campaign import CampaignError, finished_result, write_csv
from studies.pool import Pool, campaign_progress
from studies.study_file import Study, StudyError, check_study_worlds, load_study
from studies.trial_process import PlanItem
from trial_record.records import Fields, RecordError, parse_json, read_text
from trial_record.result import TrialResult

STUDY_COPY = 'study.yaml'
STUDY_STATE = 'study.json'
REPORT = 'study.md'


class StudyStopped(Exception):
    """The user stopped the study (its finished trials are kept)."""


def check(given: str) -> Tuple[Study, Path]:
    """The study file (a path, or package://), checked with its worlds (StudyError /
    CampaignError, one line); and where it is."""
    from world_description.resources import ResourceError, resolve_resource
    try:
        path = resolve_resource(given)
    except (ResourceError, ValueError) as exc:
        raise StudyError(f'--study {given}: {exc}') from None
    study = load_study(path)
    from studies.plan import check_world
    check_world(study.world)
    with tempfile.TemporaryDirectory(prefix='run_trials-study-') as scratch:
        check_study_worlds(study, Path(scratch))
    return study, path


def claim(study: Study, path: Path, out: Path, resume: bool) -> None:
    """The study's directory (held by this runner): new, or (``resume``) the same study's
    (CampaignError otherwise)."""
    state = out / STUDY_STATE
    if state.exists():
        held = _read_state(state)
        if not resume:
            raise CampaignError(f'{out} holds a study already ({STUDY_STATE}): go on with '
                                f'--resume {out}, or give another --out')
        if held != study.digest:
            raise CampaignError(f'{path} is not the study in {out} (its {STUDY_COPY} asks '
                                'something else): give another --out')
    elif any(out.glob('trial_*')):
        raise CampaignError(f'{out} holds trials but no {STUDY_STATE}: not a study\'s '
                            'directory; give another --out')
    if not (out / STUDY_COPY).exists() or not (out / STUDY_COPY).samefile(path):
        shutil.copyfile(path, out / STUDY_COPY)
    scratch_state = state.with_name(state.name + '.new')
    scratch_state.write_text(json.dumps({'study': study.digest, 'file': str(path)}, indent=1))
    os.replace(scratch_state, state)


def _read_state(path: Path) -> str:
    try:
        f = Fields(parse_json(read_text(path, 'a study state', 65536), str(path)), str(path))
        f.only(('study', 'file', 'answer'))
        return f.text('study', '', limit=64)
    except RecordError as exc:
        raise CampaignError(str(exc)) from None


class StudyTrials:
    """Runs a study's trials on ``pool``: a trial whose result is in ``out`` already (made by
    this code) is taken as it is."""

    def __init__(self, pool: Pool, out: Path, code: str, say: Callable[[str], None],
                 progress_period: float) -> None:
        self.pool, self.out, self.code, self.say = pool, out, code, say
        self.results: Dict[int, TrialResult] = {}
        self.reused = self.ran = 0
        self._period = progress_period

    def __call__(self, items: List[PlanItem]) -> List[TrialResult]:
        got: Dict[int, TrialResult] = {}
        pending = []
        for item in items:
            r = finished_result(self.out, item, self.code)
            if r is not None:
                got[item['trial']] = r
                self.reused += 1
            else:
                pending.append(item)
        try:
            while pending or self.pool.busy():
                while pending and self.pool.has_room():
                    self.pool.submit(pending.pop(0))
                r = self.pool.wait(self._period)
                if r is None:
                    states, _ = campaign_progress(self.pool, list(self.results.values()), 0)
                    self.say('[study] running: ' + ('; '.join(
                        f'trial {p.trial}: {p.sim_time:.0f} s sim, {p.delivered}/{p.total} '
                        f'delivered' for p in states) or 'starting')
                        + f'; {self.ran} run, {self.reused} taken')
                    continue
                got[r.trial if r.trial is not None else -1] = r
                self.ran += 1
                self.say(_finished(r))
                self.results[r.trial or 0] = r
                write_csv(list({**self.results, **got}.values()), self.out / 'trials.csv')
        except KeyboardInterrupt:
            self.pool.stop()
            raise StudyStopped() from None
        self.results.update(got)
        return [got[item['trial']] for item in items if item['trial'] in got]


def _finished(r: TrialResult) -> str:
    point = ', '.join(f'{k} {v:g}' for k, v in r.parameters.items())
    rate = (f'{r.handling_success_rate:.0%}' if math.isfinite(r.handling_success_rate)
            else '-')
    return (f'[study] trial {r.trial} ({point}; seed {r.scenario_seed}): {r.status}, '
            f'{r.completion_time:.1f} s, handling {rate}, wall {r.run.wall_time:.0f} s')


def run_study(study: Study, pool: Pool, out: Path, code: str, progress_period: float) -> int:
    """Run the study's trials and write its answer; the exit code."""
    started = time.monotonic()

    def say(line: str) -> None:
        print(line, flush=True)
    trials = StudyTrials(pool, out, code, say, progress_period)
    kind = 'search' if study.search else 'screening'
    where = pool.describe()         # (a Ray pool cannot say it once closed)
    say(f'[study] {study.question or study.path}: a {kind} over '
        f'{", ".join(f.name for f in study.factors)}, {where}, into {out}')
    try:
        if study.search is not None:
            lines, answer = _search(study, trials, pool.capacity, out, say)
        else:
            lines, answer = _screen(study, trials, out)
    except (StudyStopped, KeyboardInterrupt) as exc:
        if isinstance(exc, KeyboardInterrupt):
            pool.stop()
        pool.close()
        write_csv(list(trials.results.values()), out / 'trials.csv')
        say(f'[study] stopped: {len(trials.results)} trials kept in {out}; '
            f'run_trials --study {out / STUDY_COPY} --resume {out} goes on')
        return 130
    pool.close()
    write_csv(list(trials.results.values()), out / 'trials.csv')
    wall = time.monotonic() - started
    head = [f'# Study: {study.question or study.path}', '',
            f'World `{study.world}`, study seed {study.seed}; {len(trials.results)} trials '
            f'({trials.ran} run now, {trials.reused} taken from this directory), {wall:.0f} s '
            f'of wall time, {where}; code {code}. The study file: '
            f'[{STUDY_COPY}]({STUDY_COPY}); each trial in its `trial_NNN` directory (re-run, '
            'compare and storyboard take them), all of them in `trials.csv`.', '']
    (out / REPORT).write_text('\n'.join(head + lines) + '\n')
    state = json.loads((out / STUDY_STATE).read_text())
    state['answer'] = answer
    (out / STUDY_STATE).write_text(json.dumps(state, indent=1, default=str))
    say(f'[study] report {out / REPORT}')
    return 0


def _search(study: Study, trials: StudyTrials, batch: int, out: Path,
            say: Callable[[str], None]) -> Any:
    from studies.study_report import search_lines, search_plot
    from studies.study_search import Searcher
    searcher = Searcher(study, trials, batch, say)
    answer = searcher.run()
    say(f'[study] {answer.summary}')
    search_plot(study, answer, out / 'study_search.png')
    best = answer.best
    return search_lines(study, answer), {
        'summary': answer.summary, 'settled': answer.settled, 'trials': answer.trials,
        'best': None if best is None else {'values': best.values, 'trials': [
            r.trial for r in best.results]}}


def _screen(study: Study, trials: StudyTrials, out: Path) -> Any:
    from studies import study_screen
    items = study_screen.plan(study)
    results = trials(items)
    x, ys = study_screen.responses(study, items, results)
    ranked = {name: study_screen.effects(study, x, y) for name, y in ys.items()}
    study_screen.plot(study, ranked, out / 'study_effects.png')
    assert study.screening is not None
    lines = ['## Which factors matter', '',
             f'A Latin hypercube of {study.screening.points} settings x '
             f'{study.screening.replicates} trials over {len(study.factors)} factors '
             f'({len(x)} settings ran). Each factor\'s main effect is the change in the '
             'response from its low end to its high end, all others held '
             '(least squares over the design, 95 % interval); RBD-FAST S1 is the share of the '
             'response\'s variance it explains alone (SALib, 95 % bootstrap interval).', '',
             '| factor | low | high |', '|---|---|---|']
    lines += [f'| {f.name} | {f.low:g} | {f.high:g} |' for f in study.factors]
    lines += ['', '![each factor\'s effect on each response](study_effects.png)', '']
    answer: Dict[str, Optional[List[str]]] = {}
    for name, effects in ranked.items():
        lines += study_screen.ranking_lines(name, effects)
        answer[name] = [e.factor for e in effects] or None
        if effects:
            print(f'[study] {name}: ' + ', '.join(f'{e.factor} {e.effect:+.3g}'
                                                  for e in effects), flush=True)
    return lines, {'ranking': answer}


__all__ = ['StudyError', 'check', 'claim', 'run_study']
