"""Studies (studies.study_file, study_search, study_screen) on made-up cells: the study file's
checks, the constraint's decisions, the search against a dense sweep of the same cell, and the
screening's ranking."""
from __future__ import annotations

import json
import math
import random
from pathlib import Path
from typing import Callable, Dict, List

import pytest
import yaml

from studies.study_file import StudyError, load_study, parse_study
from studies.study_screen import effects, plan, responses
from studies.study_search import Searcher, decide
from studies.sweep import wilson
from studies.trial_process import PlanItem
from trial_record.result import RunInfo, TrialResult

PERTURBED = 'package://world_description/worlds/pipeline_cell_perturbed.yaml'
MATERIALS = 8


def _study(**over: object) -> Dict[str, object]:
    data: Dict[str, object] = {
        'question': 'the fastest belt', 'world': PERTURBED, 'seed': 3,
        'factors': {'belt_speed': {'low': 0.05, 'high': 0.35, 'step': 0.01}},
        'search': {'maximise': 'belt_speed',
                   'subject_to': {'response': 'handling', 'at_least': 0.95},
                   'trials_per_setting': 10, 'budget': 33}}
    data.update(over)
    return data


def _result(item: PlanItem, handled: int, time_s: float = 60.0) -> TrialResult:
    return TrialResult(status='completed' if handled == MATERIALS else 'incomplete',
                       completion_time=time_s, scenario_seed=item['seed'],
                       belt_speed=item['belt_speed'], parameters=dict(item['parameters']),
                       total=MATERIALS, handled_verified=handled, identified_correct=MATERIALS,
                       grasp_attempts=MATERIALS, grasp_successes=handled,
                       run=RunInfo(trial=item['trial']))


def _cell(loses: Callable[[PlanItem], int]) -> Callable[[List[PlanItem]], List[TrialResult]]:
    """A made-up cell: each trial loses ``loses(item)`` materials; every trial it runs is
    counted in ``ran``."""
    def run(items: List[PlanItem]) -> List[TrialResult]:
        run.ran += len(items)                                     # type: ignore[attr-defined]
        return [_result(i, MATERIALS - loses(i)) for i in items]
    run.ran = 0                                                   # type: ignore[attr-defined]
    return run


# -- the study file ------------------------------------------------------------------------

@pytest.mark.parametrize('change, words', [
    ({'factors': {}}, 'factors must be a mapping'),
    ({'factors': {'belt_speed': {'low': 0.3, 'high': 0.1}}}, 'factors.belt_speed must be'),
    ({'factors': {'belt_speed': [0.1, 0.9]}}, 'belt speeds within'),
    ({'factors': {'bad name!': [0, 1]}}, 'a factor is belt_speed'),
    ({'search': {'maximise': 'nothing'}}, 'search.maximise must be a factor'),
    ({'search': {'maximise': 'belt_speed'}}, 'asks for a constraint'),
    ({'search': {'minimise': 'completion_time', 'budget': 3, 'trials_per_setting': 5}},
     'search.budget must be'),
    ({'search': {'maximise': 'belt_speed', 'subject_to': {'response': 'handling',
                                                          'at_least': 1.5}}},
     'search.subject_to must be'),
    ({'screening': {'points': 8}}, 'give one of search'),
    ({'colour': 'red'}, "unknown keys ['colour']"),
    ({'seed': -1}, 'seed must be'),
    ({'responses': ['handling', 'speed']}, 'responses must be'),
])
def test_a_wrong_study_is_one_line_naming_its_key(change: Dict[str, object], words: str
                                                  ) -> None:
    with pytest.raises(StudyError) as err:
        parse_study(_study(**change), 'my.yaml')
    assert words in str(err.value) and str(err.value).startswith('my.yaml: ')
    assert '\n' not in str(err.value)


def test_a_screening_needs_points_for_its_factors() -> None:
    data = _study(factors={f'perturbations.camera.{k}': [0, 1] for k in 'abcd'},
                  screening={'points': 10})
    del data['search']
    with pytest.raises(StudyError, match=r'screening.points must be an integer within 16'):
        parse_study(data, 's.yaml')


def test_a_study_file_that_is_not_yaml_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / 's.yaml'
    path.write_text('factors: [\n')
    with pytest.raises(StudyError, match='not valid YAML at line'):
        load_study(path)
    with pytest.raises(StudyError, match='does not exist'):
        load_study(tmp_path / 'none.yaml')


def test_the_same_study_has_the_same_digest(tmp_path: Path) -> None:
    a, b = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    a.write_text(yaml.safe_dump(_study()))
    b.write_text(yaml.safe_dump(_study(seed=4)))
    assert load_study(a).digest == load_study(a).digest != load_study(b).digest


# -- the constraint's decisions ------------------------------------------------------------

def test_a_setting_is_decided_as_its_full_sample_would_decide_it() -> None:
    rule = parse_study(_study(), 's').search.constraint           # type: ignore[union-attr]
    assert decide(80, 80, 10, 10, rule)[0] is True                # lower bound 0.954
    assert decide(79, 80, 10, 10, rule)[0] is False
    assert decide(8, 8, 1, 10, rule)[0] is None                   # not yet
    assert decide(7, 8, 1, 10, rule)[0] is False                  # cannot reach it now
    for s in range(70, 81):          # never before the full sample would say the same
        for k in range(1, 11):
            got = min(s, 8 * k)
            verdict = decide(got, 8 * k, k, 10, rule)[0]
            if verdict is not None:
                final = wilson(got + 8 * (10 - k), 80)[0] >= 0.95 if verdict else False
                assert verdict == final


# -- the search ----------------------------------------------------------------------------

def _boundary_cell(edge: float) -> Callable[..., List[TrialResult]]:
    """Perfect up to ``edge`` m/s; above it a trial loses a material with a chance of a half
    at the edge, more the faster (drawn from the trial's seed and speed)."""
    def lost(i: PlanItem) -> int:
        chance = 0.5 + 5.0 * (i['belt_speed'] - edge)
        draw = random.Random(f'{i["seed"]}-{i["belt_speed"]:.4f}').random()
        return int(i['belt_speed'] > edge + 1e-9 and draw < chance)
    return _cell(lost)


def _dense_answer(run: Callable[..., List[TrialResult]], speeds: List[float]) -> float:
    """The fastest speed of a dense sweep (10 trials each) that meets the constraint."""
    from studies.plan import trial_plan
    seeds = trial_plan(10, 0, 3, (0.1, 0.16))
    ok = []
    for v in speeds:
        items = [PlanItem(trial=k, seed=s['seed'], belt_speed=v, parameters={'belt_speed': v})
                 for k, s in enumerate(seeds)]
        rs = run(items)
        if wilson(sum(r.handled_verified for r in rs), sum(r.total for r in rs))[0] >= 0.95:
            ok.append(v)
    return max(ok)


@pytest.mark.parametrize('edge', [0.083, 0.17, 0.213, 0.29, 0.35])
def test_the_search_finds_the_dense_sweeps_answer_with_a_third_of_its_trials(edge: float
                                                                             ) -> None:
    study = parse_study(_study(), 's')
    cell = _boundary_cell(edge)
    lines: List[str] = []
    answer = Searcher(study, cell, 2, lines.append).run()
    dense = _dense_answer(_boundary_cell(edge), [round(0.05 + 0.01 * k, 2) for k in range(31)])
    assert answer.best is not None and answer.settled, answer.summary
    assert abs(answer.best.values['belt_speed'] - dense) <= 0.01 + 1e-9
    assert answer.trials == cell.ran <= 33 <= 310 / 3          # type: ignore[attr-defined]
    assert 'settled' in answer.summary
    assert {line.split(':')[0] for line in lines} == {f'[study] setting {s.index}'
                                                      for s in answer.settings}


def test_a_search_where_nothing_meets_the_constraint_says_so() -> None:
    study = parse_study(_study(), 's')
    answer = Searcher(study, _cell(lambda i: 1), 2, lambda line: None).run()
    assert answer.best is None and not answer.settled
    assert 'no setting of the 17 tried meets' in answer.summary and answer.trials == 33
    # (Each failed at its first trials: the ends, then the interior coarse to fine.)
    assert [s.values['belt_speed'] for s in answer.settings[:5]] == [0.35, 0.05, 0.2, 0.13,
                                                                       0.27]


def test_a_search_whose_ends_fail_finds_what_meets_it_inside() -> None:
    """The perturbed cell at 0.9: both ends fail (two unlucky seeds at 0.05 m/s), 0.08 meets
    it: a search that stopped at its ends said no speed does."""
    study = parse_study(_study(), 's')
    answer = Searcher(study, _cell(lambda i: 0 if 0.1 <= i['belt_speed'] <= 0.15 else 1), 2,
                      lambda line: None).run()
    assert answer.best is not None and answer.best.values['belt_speed'] == 0.15
    assert answer.settled and answer.trials <= 33


def test_a_search_stops_at_its_budget() -> None:
    study = parse_study(_study(search={
        'maximise': 'belt_speed', 'subject_to': {'response': 'handling', 'at_least': 0.95},
        'trials_per_setting': 10, 'budget': 12}), 's')
    answer = Searcher(study, _boundary_cell(0.2), 2, lambda line: None).run()
    assert answer.trials <= 12 and not answer.settled


def test_a_search_of_a_response_minimises_it_under_the_constraint() -> None:
    data = _study(factors={'belt_speed': {'low': 0.05, 'high': 0.35, 'step': 0.01},
                           'perturbations.camera.pixel_noise': {'low': 0, 'high': 16}},
                  search={'minimise': 'completion_time', 'trials_per_setting': 2,
                          'budget': 80, 'explore': 8,
                          'subject_to': {'response': 'handling', 'at_least': 0.6}})
    study = parse_study(data, 's')

    def run(items: List[PlanItem]) -> List[TrialResult]:
        out = []
        for i in items:            # faster belt, shorter run; noise over 8 loses materials
            lost = 4 if i['parameters']['perturbations.camera.pixel_noise'] > 8 else 0
            out.append(_result(i, MATERIALS - lost, 100.0 - 150.0 * i['belt_speed']))
        return out
    answer = Searcher(study, run, 2, lambda line: None).run()
    assert answer.best is not None
    assert answer.best.values['perturbations.camera.pixel_noise'] <= 8
    assert answer.best.values['belt_speed'] >= 0.25, answer.summary


# -- the screening -------------------------------------------------------------------------

def _screening(seed: int) -> Dict[str, object]:
    names = ['camera.position_error', 'robots.joint_offset', 'camera.pixel_noise',
             'materials.mass_spread']
    data = _study(seed=seed, screening={'points': 32},
                  factors={f'perturbations.{n}': [0.0, 1.0] for n in names},
                  responses=['handling', 'completion_time'])
    del data['search']
    return data


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_the_screening_ranks_the_factors_by_their_effect(seed: int) -> None:
    study = parse_study(_screening(seed), 's')
    noise = random.Random(seed)

    def lost(p: Dict[str, float]) -> int:  # position error matters most, joint offset next
        x = (5.0 * p['perturbations.camera.position_error']
             + 2.5 * p['perturbations.robots.joint_offset'] + noise.uniform(0.0, 1.0))
        return min(MATERIALS, int(x))
    items = plan(study)
    assert len(items) == 32 and len({i['seed'] for i in items}) == 32
    results = [_result(i, MATERIALS - lost(i['parameters'])) for i in items]
    x, ys = responses(study, items, results)
    ranked = effects(study, x, ys['handling'])
    assert [e.factor for e in ranked[:2]] == ['perturbations.camera.position_error',
                                              'perturbations.robots.joint_offset']
    assert ranked[0].high < 0.0 and ranked[1].high < 0.0       # both clearly harmful
    assert all(math.isfinite(e.s1) for e in ranked)
    # (Completion time does not vary here: no effect is clear of zero.)
    assert all(e.low <= 0.0 <= e.high for e in effects(study, x, ys['completion_time']))


# -- the study's directory -----------------------------------------------------------------

def test_a_directory_resumes_only_its_own_study(tmp_path: Path) -> None:
    from studies.campaign import CampaignError
    from studies.study import STUDY_STATE, claim
    a, b = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    a.write_text(yaml.safe_dump(_study()))
    b.write_text(yaml.safe_dump(_study(seed=9)))
    out = tmp_path / 'out'
    out.mkdir()
    claim(load_study(a), a, out, resume=False)
    assert (out / 'study.yaml').read_text() == a.read_text()
    with pytest.raises(CampaignError, match='holds a study already'):
        claim(load_study(a), a, out, resume=False)
    with pytest.raises(CampaignError, match='is not the study in'):
        claim(load_study(b), b, out, resume=True)
    # A finished study (its answer written) resumes: every trial is taken, the report again.
    state = json.loads((out / STUDY_STATE).read_text())
    (out / STUDY_STATE).write_text(json.dumps({**state, 'answer': {'summary': 'x'}}))
    claim(load_study(out / 'study.yaml'), out / 'study.yaml', out, resume=True)
    (out / STUDY_STATE).write_text('{"study": "x", "extra": 1}')
    with pytest.raises(CampaignError, match='extra'):
        claim(load_study(a), a, out, resume=True)
    campaign = tmp_path / 'campaign'
    (campaign / 'trial_000').mkdir(parents=True)
    with pytest.raises(CampaignError, match='holds trials of no campaign or study'):
        claim(load_study(a), a, campaign, resume=False)
