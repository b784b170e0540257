"""``run_trials --study FILE``: a study's trials run on a campaign's pool (two at a time here,
or a Ray cluster), each a normal trial directory, and its answer written up.

A study's directory holds the study file as given (``study.yaml``), what it is
(``study.json``: its hash and its physics step), its trials (``trial_NNN``), ``trials.csv`` and,
at the end, ``study.md`` with its plot. ``--resume DIR`` runs the study again from the start,
taking every trial whose result is there and ran what it would run now (campaign.Reuse: the
trial ran the cell to an outcome, with the same seed, belt speed, setting, world, physics step
and code) instead of running it: the search, seeded, proposes the same settings in the same
order, so it goes on where it stopped. A trial that does not run (its processes fail, its
nodes never come up) stops the study without an answer: it is no evidence about the cell.
"""
from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from ros_common.outputs import write_file, write_text
from studies import directory
from studies.campaign import CampaignError, Reuse, check_plan, finished_result, write_csv
from studies.directory import STUDY_COPY, STUDY_STATE
from studies.pool import Pool, campaign_progress
from studies.study_file import Study, StudyError, check_study_worlds, load_study
from studies.trial_graph import TIME_STEP
from studies.trial_process import PlanItem
from trial_record.records import Fields, RecordError, parse_json, read_text
from trial_record.result import TrialResult

REPORT = 'study.md'
# The exit code of a study that stopped because a trial did not run (its answer would rest on
# trials that say nothing about the cell).
TRIALS_DID_NOT_RUN = 1


class StudyStopped(Exception):
    """The user stopped the study (its finished trials are kept)."""


class TrialsDidNotRun(Exception):
    """A trial of the study ended without an outcome of the cell (``TrialResult.ran``): the
    study stops without an answer (its finished trials are kept)."""

    def __init__(self, failed: List[TrialResult]) -> None:
        super().__init__(f'{len(failed)} trials did not run')
        self.failed = failed


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


def claim(study: Study, path: Path, out: Path, resume: bool,
          time_step: Optional[float] = None) -> float:
    """The study's directory (held by this runner): new, or (``resume``) the same study's
    (CampaignError otherwise); and the physics step its trials run at: ``time_step`` as
    given, else the resumed study's, else the default."""
    try:
        directory.claim(out, directory.STUDY, resume)
    except directory.DirectoryError as exc:
        raise CampaignError(str(exc)) from None
    state = out / STUDY_STATE
    stored: Optional[float] = None
    if resume:
        held, stored = _read_state(state)
        if held != study.digest:
            raise CampaignError(f'{path} is not the study in {out} (its {STUDY_COPY} asks '
                                'something else): give another --out')
    if time_step is not None:
        step = float(check_plan({'time_step': time_step}, '--time-step')['time_step'])
        if stored is not None and step != stored:
            raise CampaignError(f'--time-step {step:g} differs from the study being resumed '
                                f'({stored:g}, in {state})')
    else:
        step = stored if stored is not None else TIME_STEP
    copy = out / STUDY_COPY
    if copy.is_dir() and not copy.is_symlink():
        raise CampaignError(f'{copy} is a directory, where the study keeps its file: give '
                            'another --out')
    try:
        if not (copy.is_file() and copy.samefile(path)):
            write_file(copy, path.read_bytes())
        write_text(state, json.dumps({'study': study.digest, 'file': str(path),
                                      'time_step': step}, indent=1))
    except OSError as exc:
        raise CampaignError(f'{out}: cannot write the study\'s files '
                            f'({exc.strerror or exc})') from None
    return step


def _read_state(path: Path) -> Tuple[str, Optional[float]]:
    """A study state's hash, and its trials' physics step (None: not recorded)."""
    try:
        f = Fields(parse_json(read_text(path, 'a study state', 65536), str(path)), str(path))
        f.only(('study', 'file', 'answer', 'time_step'))
        digest = f.text('study', '', limit=64)
        step = f.number('time_step', 1e-4, 1.0, math.nan, nan=True)
    except RecordError as exc:
        raise CampaignError(str(exc)) from None
    return digest, (step if math.isfinite(step) else None)


class StudyTrials:
    """Runs a study's trials on ``pool``: a trial whose result is in ``out`` already, and ran
    what it would run now (``reuse``), is taken as it is. A trial that does not run stops the
    study (TrialsDidNotRun) once the trials running beside it end."""

    def __init__(self, pool: Pool, out: Path, reuse: Reuse, say: Callable[[str], None],
                 progress_period: float) -> None:
        self.pool, self.out, self.reuse, self.say = pool, out, reuse, say
        self.results: Dict[int, TrialResult] = {}
        self.reused = self.ran = 0
        self._period = progress_period

    def __call__(self, items: List[PlanItem]) -> List[TrialResult]:
        got: Dict[int, TrialResult] = {}
        pending = []
        for item in items:
            r = finished_result(self.out, item, self.reuse)
            if r is not None:
                got[item['trial']] = self.results[item['trial']] = r
                self.reused += 1
            else:
                pending.append(item)
        failed: List[TrialResult] = []
        try:
            while (pending and not failed) or self.pool.busy():
                while pending and not failed and self.pool.has_room():
                    self.pool.submit(pending.pop(0))
                r = self.pool.wait(self._period)
                if r is None:
                    states, _ = campaign_progress(self.pool, list(self.results.values()), 0)
                    self.say('[study] running: ' + ('; '.join(
                        f'trial {p.trial}: {p.sim_time:.0f} s sim, {p.delivered}/{p.total} '
                        f'delivered' for p in states) or 'starting')
                        + f'; {self.ran} run, {self.reused} taken')
                    continue
                self.ran += 1
                self.say(_finished(r))
                if not r.ran:
                    failed.append(r)
                    continue
                got[r.trial if r.trial is not None else -1] = r
                self.results[r.trial or 0] = r
                write_csv(list(self.results.values()), self.out / 'trials.csv')
        except KeyboardInterrupt:
            self.pool.stop()
            raise StudyStopped() from None
        if failed:
            raise TrialsDidNotRun(failed)
        return [got[item['trial']] for item in items if item['trial'] in got]


def _finished(r: TrialResult) -> str:
    point = ', '.join(f'{k} {v:g}' for k, v in r.parameters.items())
    rate = (f'{r.handling_success_rate:.0%}' if math.isfinite(r.handling_success_rate)
            else '-')
    return (f'[study] trial {r.trial} ({point}; seed {r.scenario_seed}): {r.status}, '
            f'{r.completion_time:.1f} s, handling {rate}, wall {r.run.wall_time:.0f} s')


def run_study(study: Study, pool: Pool, out: Path, reuse: Reuse,
              progress_period: float) -> int:
    """Run the study's trials and write its answer; the exit code."""
    started = time.monotonic()

    def say(line: str) -> None:
        print(line, flush=True)
    trials = StudyTrials(pool, out, reuse, say, progress_period)
    kind = 'search' if study.search else 'screening'
    where = pool.describe()         # (a Ray pool cannot say it once closed)
    say(f'[study] {study.question or study.path}: a {kind} over '
        f'{", ".join(f.name for f in study.factors)}, {where}, into {out}')
    resume = f'run_trials --study {out / STUDY_COPY} --resume {out} goes on'
    try:
        if study.search is not None:
            lines, answer = _search(study, trials, pool.capacity, out, say)
        else:
            lines, answer = _screen(study, trials, out)
    except (StudyStopped, KeyboardInterrupt) as exc:
        if isinstance(exc, KeyboardInterrupt):
            pool.stop()
        pool.close()
        # (Trials that ended while the study stopped are kept, as a campaign keeps them.)
        trials.results.update({r.trial: r for r in pool.drain()
                               if r.ran and r.trial is not None})
        write_csv(list(trials.results.values()), out / 'trials.csv')
        say(f'[study] stopped: {len(trials.results)} trials kept in {out}; {resume}')
        return 130
    except TrialsDidNotRun as exc:
        pool.close()
        write_csv(list(trials.results.values()), out / 'trials.csv')
        for r in exc.failed:
            say(f'[study] trial {r.trial} did not run: {r.status}: '
                f'{(r.message or "no message").splitlines()[0][:300]}')
        say(f'[study] no answer: {len(exc.failed)} trials did not run, and a trial that did '
            'not run says nothing about the cell; '
            f'{len(trials.results)} trials that ran are kept in {out}; once the cause is '
            f'fixed, {resume}')
        return TRIALS_DID_NOT_RUN
    pool.close()
    write_csv(list(trials.results.values()), out / 'trials.csv')
    wall = time.monotonic() - started
    head = [f'# Study: {study.question or study.path}', '',
            f'World `{study.world}`, study seed {study.seed}, physics step '
            f'{reuse.time_step:g} s; {len(trials.results)} trials ({trials.ran} run now, '
            f'{trials.reused} taken from this directory), {wall:.0f} s of wall time, {where}; '
            f'code {reuse.code}. The study file: [{STUDY_COPY}]({STUDY_COPY}); each trial in '
            'its `trial_NNN` directory (re-run, compare and storyboard take them), all of '
            'them in `trials.csv`.', '']
    write_text(out / REPORT, '\n'.join(head + lines) + '\n')
    state = json.loads((out / STUDY_STATE).read_text())
    state['answer'] = answer
    write_text(out / STUDY_STATE, json.dumps(state, indent=1, default=str))
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
