"""A study file: a question about a cell, asked of its trials (docs/studies.md).

    question: the fastest belt the perturbed cell keeps up with   # what it asks, in words
    world: package://world_description/worlds/pipeline_cell_perturbed.yaml
    seed: 2026                       # the study's seed: its design and its scenario seeds
    factors:                         # belt_speed, or any number of the world by its path
      belt_speed: {low: 0.05, high: 0.35, step: 0.01}
    search:                          # or screening: (one of the two)
      maximise: belt_speed           # or minimise:; a factor or a response
      subject_to: {response: handling, at_least: 0.95}
      trials_per_setting: 10
      budget: 33

Every key is checked when the file is read, before any trial runs: a wrong one is one line
naming the file, the key and what it must be (``StudyError``).
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

from studies.sweep import _NAME, RATES, TRIAL_PARAMETERS, SweepError, check_names, point_world
from trial_record.result import COUNTS, MAX_PARAMETERS, TrialResult
from world_description.world_config import WorldConfigError
from world_description.world_loading import read_yaml

MAX_BELT_SPEED = 0.5                 # m/s (as a campaign's)
MAX_STUDY_TRIALS = 10_000
MAX_SETTING_TRIALS = 200
MAX_GRID = 100_000               # values on a factor's grid (low + k * step)
# The responses a study reads from a result: each rate (a proportion over materials, or grasp
# attempts), and a number of it.
NUMBERS = ('completion_time',) + COUNTS
RESPONSES = tuple(RATES) + NUMBERS
# z of a two-sided interval at each confidence the constraint takes.
Z_OF = {0.9: 1.6449, 0.95: 1.96, 0.99: 2.5758}


class StudyError(ValueError):
    """A study file that cannot be run; the message is the line to print."""


@dataclass(frozen=True)
class Factor:
    name: str
    low: float
    high: float
    step: float = 0.0                # 0: continuous

    def snap(self, value: float) -> float:
        """``value`` on the factor's grid (low + k * step), within its range."""
        value = min(self.high, max(self.low, value))
        if self.step > 0.0:
            value = self.low + round((value - self.low) / self.step) * self.step
            value = min(self.high, value)
        return round(value, 10)


@dataclass(frozen=True)
class Constraint:
    response: str                    # a rate (RATES)
    at_least: float                  # its Wilson lower bound must be this or more
    confidence: float = 0.95

    @property
    def z(self) -> float:
        return Z_OF[self.confidence]


@dataclass(frozen=True)
class Search:
    objective: str                   # a factor or a response
    maximise: bool
    constraint: Optional[Constraint]
    trials_per_setting: int          # the most a setting gets (the constraint's sample)
    first_trials: int                # a setting's first batch, before any decision
    budget: int                      # trials at most, over all settings
    explore: int                     # settings the sampler proposes freely


@dataclass(frozen=True)
class Screening:
    points: int                      # the Latin hypercube's points
    replicates: int                  # trials at each


@dataclass(frozen=True)
class Study:
    path: str
    question: str
    world: str
    seed: int
    factors: Tuple[Factor, ...]
    responses: Tuple[str, ...]
    belt_speed: Tuple[float, float]  # drawn per trial, unless a factor
    search: Optional[Search] = None
    screening: Optional[Screening] = None
    source: Dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def digest(self) -> str:
        """What the study asks, as a short hash: a directory resumes only its own study."""
        text = json.dumps(self.source, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def factor(self, name: str) -> Optional[Factor]:
        return next((f for f in self.factors if f.name == name), None)


def response_of(result: TrialResult, name: str) -> Tuple[float, float]:
    """A response of one trial: a rate's (successes, n), or a number's (value, 1)."""
    if name in RATES:
        s, n = RATES[name](result)
        return float(s), float(n)
    return float(getattr(result, name)), 1.0


def load_study(path: Path) -> Study:
    """A study file, read and checked (StudyError)."""
    try:
        data = read_yaml(Path(path), 'study file')
    except WorldConfigError as exc:
        raise StudyError(str(exc)) from None
    return parse_study(data, str(path))


def _number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _integer(value: Any) -> bool:
    """An integer, not a truth value (YAML's ``true`` is Python's 1)."""
    return isinstance(value, int) and not isinstance(value, bool)


def parse_study(data: Any, where: str) -> Study:
    """A study's mapping as read from ``where`` (StudyError naming the first wrong key)."""
    def bad(key: str, what: str) -> StudyError:
        return StudyError(f'{where}: {key} must be {what}')
    if not isinstance(data, dict):
        raise StudyError(f'{where}: a study file is a mapping (question, world, seed, factors, '
                         'and search or screening)')
    known = ('question', 'world', 'seed', 'factors', 'responses', 'belt_speed', 'search',
             'screening')
    unknown = sorted(str(k) for k in data if k not in known)
    if unknown:
        raise StudyError(f'{where}: unknown keys {unknown} (a study has {", ".join(known)})')
    question = data.get('question', '')
    if not isinstance(question, str) or len(question) > 500:
        raise bad('question', 'text (at most 500 characters)')
    world = data.get('world')
    if not isinstance(world, str) or not world.strip():
        raise bad('world', 'the path or package:// address of a world file')
    seed = data.get('seed', 2026)
    if not (_integer(seed) and 0 <= seed < 2 ** 31):
        raise bad('seed', f'an integer within 0..{2 ** 31 - 1}')
    factors = _factors(data.get('factors'), where)
    belt = data.get('belt_speed', [0.10, 0.16])
    if not (isinstance(belt, list) and len(belt) == 2 and all(_number(v) for v in belt)
            and 0.0 < belt[0] <= belt[1] <= MAX_BELT_SPEED):
        raise bad('belt_speed', f'[LO, HI] m/s with 0 < LO <= HI <= {MAX_BELT_SPEED} (the '
                  'trials\' belt speeds when it is no factor)')
    if ('search' in data) == ('screening' in data):
        raise StudyError(f'{where}: give one of search: (the best setting under a '
                         'constraint) or screening: (which factors matter)')
    search = _search(data['search'], factors, where) if 'search' in data else None
    screening = (_screening(data['screening'], len(factors), where)
                 if 'screening' in data else None)
    responses = data.get('responses', ['handling', 'completion_time'])
    if not (isinstance(responses, list) and 1 <= len(responses) <= 8
            and all(r in RESPONSES for r in responses) and len(set(responses)) == len(responses)):
        raise bad('responses', f'a list of 1-8 of {", ".join(RESPONSES)}')
    study = Study(where, question, world, seed, factors, tuple(responses),
                  (float(belt[0]), float(belt[1])), search, screening, dict(data))
    trials = (search.budget if search else screening.points * screening.replicates
              if screening else 0)
    if trials > MAX_STUDY_TRIALS:
        raise StudyError(f'{where}: the study plans {trials} trials (at most '
                         f'{MAX_STUDY_TRIALS})')
    return study


def _factors(data: Any, where: str) -> Tuple[Factor, ...]:
    if not (isinstance(data, dict) and 1 <= len(data) <= MAX_PARAMETERS):
        raise StudyError(f'{where}: factors must be a mapping of 1-{MAX_PARAMETERS} names '
                         '(belt_speed, or a number of the world by its path) to {low, high} '
                         '(and step)')
    out = []
    for name, spec in data.items():
        key = f'factors.{name}'
        if not (isinstance(name, str) and _NAME.match(name)):
            raise StudyError(f'{where}: {key}: a factor is belt_speed or a number of the world '
                             'file by its path (perturbations.camera.pixel_noise)')
        if isinstance(spec, list) and len(spec) == 2:
            spec = {'low': spec[0], 'high': spec[1]}
        if not (isinstance(spec, dict) and set(spec) <= {'low', 'high', 'step'}
                and _number(spec.get('low')) and _number(spec.get('high'))
                and spec['low'] < spec['high'] and _number(spec.get('step', 0.0))
                and 0.0 <= spec.get('step', 0.0) <= spec['high'] - spec['low']):
            raise StudyError(f'{where}: {key} must be {{low: L, high: H}} with L < H (and '
                             'step: S, 0 < S <= H - L, for values on a grid)')
        factor = Factor(name, float(spec['low']), float(spec['high']),
                        float(spec.get('step', 0.0)))
        span = factor.high - factor.low
        if not math.isfinite(span):
            raise StudyError(f'{where}: {key}: high - low must be a finite number')
        if factor.step > 0.0 and span / factor.step > MAX_GRID:
            raise StudyError(f'{where}: {key}: a step of {factor.step:g} makes '
                             f'{span / factor.step:.3g} values; at most {MAX_GRID}')
        if name == 'belt_speed' and not 0.0 < factor.low < factor.high <= MAX_BELT_SPEED:
            raise StudyError(f'{where}: {key}: belt speeds within (0, {MAX_BELT_SPEED}] m/s')
        out.append(factor)
    try:
        check_names([f.name for f in out], f'{where}: factors')
    except SweepError as exc:
        raise StudyError(str(exc)) from None
    return tuple(out)


def _search(data: Any, factors: Tuple[Factor, ...], where: str) -> Search:
    def bad(key: str, what: str) -> StudyError:
        return StudyError(f'{where}: search.{key} must be {what}')
    if not isinstance(data, dict):
        raise StudyError(f'{where}: search must be a mapping (maximise or minimise, '
                         'subject_to, trials_per_setting, budget)')
    allowed = {'maximise', 'minimise', 'subject_to', 'trials_per_setting', 'first_trials',
               'budget', 'explore'}
    if set(data) - allowed:
        raise StudyError(f'{where}: search: unknown keys {sorted(set(data) - allowed)}')
    if ('maximise' in data) == ('minimise' in data):
        raise StudyError(f'{where}: search: give one of maximise: or minimise: (a factor or '
                         'a response)')
    objective = data.get('maximise', data.get('minimise'))
    names = [f.name for f in factors]
    if objective not in names + list(RESPONSES):
        raise bad('maximise' if 'maximise' in data else 'minimise',
                  f'a factor ({", ".join(names)}) or a response ({", ".join(RESPONSES)})')
    constraint = None
    if 'subject_to' in data:
        c = data['subject_to']
        if not (isinstance(c, dict) and set(c) <= {'response', 'at_least', 'confidence'}
                and c.get('response') in RATES and _number(c.get('at_least'))
                and 0.0 < c['at_least'] < 1.0 and c.get('confidence', 0.95) in Z_OF):
            raise bad('subject_to', f'{{response: RATE, at_least: P}} with RATE one of '
                      f'{", ".join(RATES)}, 0 < P < 1 (and confidence: one of '
                      f'{", ".join(str(k) for k in Z_OF)})')
        constraint = Constraint(c['response'], float(c['at_least']),
                                float(c.get('confidence', 0.95)))
    elif objective in names:
        raise StudyError(f'{where}: search: maximising a factor asks for a constraint '
                         '(subject_to:), or the answer is the range\'s end')
    per = data.get('trials_per_setting', 10)
    if not (_integer(per) and 1 <= per <= MAX_SETTING_TRIALS):
        raise bad('trials_per_setting', f'an integer within 1..{MAX_SETTING_TRIALS}')
    first = data.get('first_trials', min(2, per))
    if not (_integer(first) and 1 <= first <= per):
        raise bad('first_trials', 'an integer within 1..trials_per_setting')
    budget = data.get('budget', 10 * per)
    if not (_integer(budget) and per <= budget <= MAX_STUDY_TRIALS):
        raise bad('budget', f'an integer within trials_per_setting..{MAX_STUDY_TRIALS}')
    # (One factor maximised or minimised under a constraint is a bracket to close by halving;
    # the sampler's free proposals are worth their trials where there is more to search.)
    bracketed = constraint is not None and len(factors) == 1 and objective == names[0]
    explore = data.get('explore', 0 if bracketed else 4)
    if not (_integer(explore) and 0 <= explore <= 100):
        raise bad('explore', 'an integer within 0..100')
    return Search(objective, 'maximise' in data, constraint, per, first, budget, explore)


def _screening(data: Any, count: int, where: str) -> Screening:
    if not (isinstance(data, dict) and set(data) <= {'points', 'replicates'}):
        raise StudyError(f'{where}: screening must be a mapping of points (the design\'s, '
                         'at least 4 per factor) and replicates')
    points = data.get('points', 8 * count)
    if not (_integer(points) and max(8, 4 * count) <= points <= MAX_STUDY_TRIALS):
        raise StudyError(f'{where}: screening.points must be an integer within '
                         f'{max(8, 4 * count)}..{MAX_STUDY_TRIALS} (at least 4 per factor, '
                         f'{count} factors)')
    replicates = data.get('replicates', 1)
    if not (_integer(replicates) and 1 <= replicates <= 100):
        raise StudyError(f'{where}: screening.replicates must be an integer within 1..100')
    return Screening(points, replicates)


def check_study_worlds(study: Study, scratch: Path) -> None:
    """The worlds at the factors' corners (all low, all high, each factor alone at either
    end) load and are checked, and each factor alone takes values across its range (its grid,
    or points inside a continuous range: a number the world takes whole, such as a count,
    refuses those): a range the world refuses stops the study before it starts."""
    from studies.plan import check_world
    world_factors = [f for f in study.factors if f.name not in TRIAL_PARAMETERS]
    if not world_factors:
        return
    lows = {f.name: f.low for f in world_factors}
    highs = {f.name: f.high for f in world_factors}
    corners: List[Dict[str, float]] = [lows, highs]
    for f in world_factors:
        corners += [{**lows, f.name: f.high}, {**highs, f.name: f.low}]
    for i, point in enumerate(corners):
        try:
            world = point_world(study.world, point, scratch / f'corner_{i}')
        except SweepError as exc:
            raise StudyError(f'{study.path}: {exc}') from None
        check_world(world)
    for f in world_factors:
        for value in _inside(f):
            try:
                point_world(study.world, {**lows, f.name: value}, scratch / 'inside')
            except SweepError as exc:
                hint = ('' if f.step > 0.0 else '; without a step, a factor takes any value '
                        'between low and high (a count needs step: 1)')
                why = str(exc).partition('gives no valid world: ')[2] or str(exc)
                raise StudyError(f'{study.path}: factors.{f.name} takes {value:g} inside its '
                                 f'range, which the world refuses: {why}{hint}') from None


# (Fractions of a continuous range where a factor is tried before the study: none of them a
# simple fraction, so that a number the world takes only whole is caught.)
_INSIDE = (0.1464, 0.5, 0.7071)
MAX_PROBES = 24


def _inside(f: Factor) -> List[float]:
    """Values of a factor inside its range, tried before the study starts: its grid (every
    value, or MAX_PROBES spread over it), or a few points of a continuous range."""
    if f.step <= 0.0:
        return [f.low + (f.high - f.low) * k for k in _INSIDE]
    count = int(math.floor((f.high - f.low) / f.step + 1e-9))
    ks = sorted({round(j * count / (MAX_PROBES - 1)) for j in range(MAX_PROBES)}
                if count >= MAX_PROBES else range(count + 1))
    return [f.snap(f.low + k * f.step) for k in ks if 0 < k < count]
