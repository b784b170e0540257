"""A study's search: the best setting of its factors under a constraint on a rate, found by
Optuna's sampler and, for one factor, narrowed by halving the gap between the best setting
that meets the constraint and the nearest one that does not.

Each setting runs the study's scenario seeds in order, a few trials at a time, and stops as
soon as the constraint is decided the way ``trials_per_setting`` trials would decide it: met
once the rate's Wilson lower bound reaches ``at_least``; failed once it cannot reach it even if
every trial still allowed came out perfect. A setting near the boundary runs more trials, one
far from it few. Pure: the trials are run by the ``RunTrials`` it is given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Tuple

from studies.plan import trial_plan
from studies.study_file import Constraint, Factor, Study, response_of
from studies.sweep import wilson
from studies.trial_process import PlanItem
from trial_record.result import TrialResult

RunTrials = Callable[[List[PlanItem]], List[TrialResult]]
# Proposals of the sampler that repeat a setting already tried, allowed in a row before the
# search stops exploring.
MAX_REPEATS = 20
# Settings without a better feasible one, after which a search of several factors (or of a
# response) stops.
PATIENCE = 6


@dataclass
class Setting:
    """One setting of the factors and the trials it ran."""
    index: int
    values: Dict[str, float]
    results: List[TrialResult] = field(default_factory=list)
    feasible: Optional[bool] = None        # None: no constraint, or not decided yet
    how: str = ''                          # why it was judged so
    provisional: bool = False              # met so far, on fewer trials than decide it

    @property
    def looks_met(self) -> bool:
        return bool(self.feasible) or self.provisional

    def counts(self, name: str) -> Tuple[float, float]:
        s = n = 0.0
        for r in self.results:
            a, b = response_of(r, name)
            s, n = s + a, n + b
        return s, n

    def mean(self, name: str) -> float:
        s, n = self.counts(name)
        return s / n if n else math.nan

    def bounds(self, c: Constraint) -> Tuple[float, float]:
        return wilson(*self.counts(c.response), z=c.z)


def decide(successes: float, n: float, trials: int, cap: int, c: Constraint
           ) -> Tuple[Optional[bool], str]:
    """The constraint after ``trials`` of at most ``cap`` trials (``successes`` of ``n``):
    met, failed, or not yet decided (None); and why, in words."""
    low, high = wilson(successes, n, c.z)
    rate = f'{successes:g}/{n:g} ({successes / n:.1%})' if n else 'nothing counted'
    if n and low >= c.at_least:
        return True, f'{rate}, {c.confidence:.0%} lower bound {low:.3f}'
    remaining = cap - trials
    if trials and n == 0:
        return (None, rate) if remaining > 0 else (False, f'{rate} after {trials} trials')
    per = n / trials if trials else 0.0
    best, _ = wilson(successes + remaining * per, n + remaining * per, c.z)
    if trials and best < c.at_least:
        return False, (f'{rate} after {trials} trials: at best {best:.3f} after {cap}'
                       if remaining > 0 else f'{rate}, lower bound {low:.3f}')
    return None, f'{rate}, lower bound {low:.3f}, upper {high:.3f}'


@dataclass
class SearchAnswer:
    settings: List[Setting]
    best: Optional[Setting]
    settled: bool
    summary: str                           # the answer and how sure it is, in words
    trials: int


class Searcher:
    """The search of one study (``study.search``), its trials run by ``run``; ``log`` gets a
    line per setting."""

    def __init__(self, study: Study, run: RunTrials, batch: int,
                 log: Callable[[str], None] = print) -> None:
        assert study.search is not None
        self.study, self.spec, self._run, self._log = study, study.search, run, log
        self.batch = max(1, batch)
        per = self.spec.trials_per_setting
        self._seeds = trial_plan(per, 0, study.seed, study.belt_speed)
        self.settings: List[Setting] = []
        self.trials = 0
        one = len(study.factors) == 1 and self.spec.objective == study.factors[0].name
        self.bracketed = one and self.spec.constraint is not None

    # -- a setting's trials ----------------------------------------------------------------
    def _items(self, setting: Setting, start: int, stop: int) -> List[PlanItem]:
        per = self.spec.trials_per_setting
        out = []
        for k in range(start, stop):
            base = self._seeds[k]
            out.append(PlanItem(trial=setting.index * per + k, seed=base['seed'],
                                belt_speed=setting.values.get('belt_speed', base['belt_speed']),
                                parameters=dict(setting.values)))
        return out

    def evaluate(self, values: Dict[str, float], full: bool = True) -> Setting:
        """A new setting's trials: until its constraint is decided (``full``), or only its
        first trials while they do not decide it against (then it is provisional)."""
        setting = Setting(len(self.settings), values)
        self.settings.append(setting)
        return self.extend(setting, full)

    def extend(self, setting: Setting, full: bool = True) -> Setting:
        """More trials of a setting, from where it stopped: until its constraint is decided
        (or all of them, without one), within the budget."""
        spec, c = self.spec, self.spec.constraint
        done = len(setting.results)
        step = spec.first_trials if done == 0 else self.batch
        setting.provisional = False
        while done < spec.trials_per_setting:
            take = min(step, spec.trials_per_setting - done, spec.budget - self.trials)
            if take <= 0:
                break
            setting.results += self._run(self._items(setting, done, done + take))
            done += take
            self.trials += take
            step = self.batch
            if c is not None:
                verdict, setting.how = decide(*setting.counts(c.response), done,
                                              spec.trials_per_setting, c)
                if verdict is not None:
                    setting.feasible = verdict
                    break
                if not full:
                    setting.provisional = True
                    setting.how += f' (provisional, after {done} trials)'
                    break
        if c is not None and setting.feasible is None and not setting.provisional:
            # (The budget ran out first: judged by what it has, which cannot be a pass.)
            setting.feasible = False
            setting.how += ' (undecided: the budget ran out)'
        self._log(self._line(setting))
        return setting

    def _line(self, s: Setting) -> str:
        values = ', '.join(f'{k} {v:g}' for k, v in s.values.items())
        verdict = (' looks like meeting the constraint' if s.provisional else
                   '' if s.feasible is None else
                   ' meets the constraint' if s.feasible else ' fails the constraint')
        objective = ('' if self.spec.objective in s.values else
                     f'; {self.spec.objective} {s.mean(self.spec.objective):.4g}')
        return (f'[study] setting {s.index}: {values}: {len(s.results)} trials{verdict}'
                f'{": " + s.how if s.how else ""}{objective} ({self.trials} trials so far)')

    # -- the search ------------------------------------------------------------------------
    def objective_of(self, s: Setting) -> float:
        name = self.spec.objective
        return s.values[name] if name in s.values else s.mean(name)

    def best(self) -> Optional[Setting]:
        ok = [s for s in self.settings if s.feasible is not False and not s.provisional
              and math.isfinite(self.objective_of(s))]
        if not ok:
            return None
        return (max if self.spec.maximise else min)(ok, key=self.objective_of)

    def _ends(self) -> List[float]:
        """A bracketed search tries the range's far end first (met there: that is the answer),
        then, if it fails there, its near end (and then its interior, coarse to fine)."""
        f = self.study.factors[0]
        return [f.high, f.low] if self.spec.maximise else [f.low, f.high]

    def _halving(self) -> Tuple[Optional[float], Optional[Setting], str]:
        """The next value of a bracketed search (None: the bracket is closed); the best
        setting that meets the constraint, or looks like it; and, when closed, why."""
        f = self.study.factors[0]
        sign = 1.0 if self.spec.maximise else -1.0
        tried = {s.values[f.name]: s for s in self.settings}
        ok = [v for v, s in tried.items() if s.looks_met]
        if not ok:
            # (Both ends failed: the interior is probed coarse to fine before the search says
            # that nothing meets the constraint; the rate need not fall with the factor.)
            probe = next((v for v in _probes(f) if v not in tried), None)
            return probe, None, ('' if probe is not None else
                                 f'no value of {f.name} on its grid meets the constraint')
        b = max(ok, key=lambda v: sign * v)
        beyond = [v for v, s in tried.items() if not s.looks_met and sign * (v - b) > 0]
        if not beyond:
            return None, tried[b], f'{b:g} meets it and is the end of the range'
        c = min(beyond, key=lambda v: sign * v)
        mid = f.snap((b + c) / 2.0)
        if mid in (b, c) or abs(c - b) <= _resolution(f):
            return None, tried[b], f'{b:g} meets it and {c:g} does not ({tried[c].how})'
        return mid, tried[b], ''

    def run(self) -> SearchAnswer:
        import optuna
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        spec = self.spec
        sampler = optuna.samplers.TPESampler(seed=self.study.seed,
                                             n_startup_trials=max(2, spec.explore))
        search = optuna.create_study(direction='maximize' if spec.maximise else 'minimize',
                                     sampler=sampler)
        space = {f.name: _distribution(optuna, f) for f in self.study.factors}
        name = self.study.factors[0].name
        planned = [{name: self._ends()[0]}] if self.bracketed else []
        explored = repeats = since_better = 0
        best_before: Optional[Setting] = None
        why, settled = '', False
        while self.trials < spec.budget:
            proposal: Optional[Dict[str, float]] = None
            if planned:
                proposal = planned.pop(0)
            elif self.bracketed and explored >= spec.explore:
                value, best, closed = self._halving()
                if value is None and best is not None and best.provisional:
                    self.extend(best)       # (the answer's trials in full: met, or go on)
                    continue
                if value is None:
                    # (Settled: the bracket closed, or every value on the grid failed.)
                    why, settled = closed, True
                    break
                proposal = {name: value}
            elif not self.bracketed and since_better >= max(PATIENCE, spec.explore):
                why = f'{since_better} settings in a row found nothing better'
                break
            else:
                explored += 1
            if proposal is not None:
                search.enqueue_trial(proposal)
            trial = search.ask(space)
            values = {f.name: f.snap(trial.params[f.name]) for f in self.study.factors}
            known = next((s for s in self.settings if s.values == values), None)
            if known is not None:
                # (The sampler proposed a setting tried already: told its result again.)
                self._tell(search, trial, known)
                repeats += 1
                if repeats > MAX_REPEATS:
                    why = 'the sampler proposes only settings tried already'
                    break
                continue
            repeats = 0
            self._tell(search, trial, self.evaluate(values, full=not self.bracketed))
            best = self.best()
            since_better = 0 if best is not best_before else since_better + 1
            best_before = best
        return SearchAnswer(self.settings, self.best(), settled,
                            self._summary(why or 'the budget ran out', settled), self.trials)

    def _tell(self, search: Any, trial: Any, s: Setting) -> None:
        c = self.spec.constraint
        if c is not None:
            # (Optuna's constraint: met at zero or less. A provisional setting counts as met.)
            low, _ = s.bounds(c)
            trial.set_constraint(c.response, 0.0 if s.looks_met else
                                 c.at_least - (low if math.isfinite(low) else 0.0))
        value = self.objective_of(s)
        search.tell(trial, value if math.isfinite(value) else None,
                    state=None if math.isfinite(value) else _failed_state())

    def _summary(self, why: str, settled: bool) -> str:
        best, spec = self.best(), self.spec
        c = spec.constraint
        wanted = (f'{"maximise" if spec.maximise else "minimise"} {spec.objective}'
                  + (f' with the {c.response} rate\'s {c.confidence:.0%} Wilson lower bound at '
                     f'least {c.at_least:g}' if c else ''))
        if best is None:
            return (f'{wanted}: no setting of the {len(self.settings)} tried meets the '
                    f'constraint ({self.trials} trials); {"settled" if settled else "not settled"}'
                    f': {why}.')
        values = ', '.join(f'{k} {v:g}' for k, v in best.values.items())
        head = f'{wanted}: {values}'
        if spec.objective not in best.values:
            head += f' ({spec.objective} {best.mean(spec.objective):.4g})'
        sure = f'{best.how}' if best.how else f'{len(best.results)} trials'
        state = 'settled' if settled else 'not settled'
        return (f'{head}, from {self.trials} trials over {len(self.settings)} settings; '
                f'{sure}; {state}: {why}.')


def _probes(f: Factor) -> List[float]:
    """The factor's values, coarse to fine: the near end (after the far one), then the middle,
    the quarters, the eighths, ... down to its resolution."""
    out: List[float] = [f.low, f.high]
    depth = 1
    while (f.high - f.low) / 2 ** depth >= _resolution(f) / 2 and depth < 12:
        for k in range(1, 2 ** depth, 2):
            v = f.snap(f.low + (f.high - f.low) * k / 2 ** depth)
            if v not in out:
                out.append(v)
        depth += 1
    return out


def _resolution(f: Factor) -> float:
    return f.step if f.step > 0.0 else (f.high - f.low) / 100.0


def _distribution(optuna: Any, f: Factor) -> Any:
    span = f.high - f.low
    if f.step > 0.0 and abs(span / f.step - round(span / f.step)) < 1e-9:
        return optuna.distributions.FloatDistribution(f.low, f.high, step=f.step)
    return optuna.distributions.FloatDistribution(f.low, f.high)


def _failed_state() -> Any:
    import optuna
    return optuna.trial.TrialState.FAIL
