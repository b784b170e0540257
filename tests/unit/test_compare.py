"""compare_runs (studies/compare.py): two runs side by side, two campaigns with their
statistics."""
import math

import pytest

from studies.compare import load_runs, main, mann_whitney, two_proportions
from trial_record.result import RunInfo, TrialResult


def test_two_proportions():
    # 45/50 against 30/50: pooled 0.75, z = 3.46, p = 0.00053
    assert two_proportions(45, 50, 30, 50) == pytest.approx(0.000532, rel=0.01)
    assert two_proportions(8, 8, 8, 8) == 1.0
    assert two_proportions(40, 50, 40, 50) == pytest.approx(1.0)
    assert math.isnan(two_proportions(1, 0, 1, 2))


def test_mann_whitney():
    a, b = [1, 2, 3, 4, 5, 6, 7, 8], [9, 10, 11, 12, 13, 14, 15, 16]
    # U = 0 of n = 8 and 8: mean 32, sd 9.52, z = -3.36, p = 0.00078
    assert mann_whitney(a, b) == pytest.approx(0.00078, rel=0.01)
    assert mann_whitney(a, a) == pytest.approx(1.0)
    assert mann_whitney([60.0] * 5, [60.0] * 5) == 1.0                # (all tied)
    assert math.isnan(mann_whitney([], [1.0]))
    assert 0.05 < mann_whitney([1, 3, 5, 7], [2, 4, 6, 8]) <= 1.0


def _trial(path, trial, handled, time, events, status=None):
    result = TrialResult(status or ('completed' if handled == 8 else 'incomplete'), time,
                         scenario_seed=trial, belt_speed=0.12, total=8, identified_correct=8,
                         handled_verified=handled, grasp_attempts=8, grasp_successes=handled,
                         events=events, youbot_path=[[0.8, 0.05], [1.2, -0.5], [1.8, -1.5]],
                         states=[[0.0, 'loader', 'pick'], [time, 'loader', 'home']],
                         run=RunInfo(trial=trial))
    result.write(path / f'trial_{trial:03d}' / 'result.json')
    return result


def test_two_runs_side_by_side(tmp_path, capsys):
    start = [0.0, 'belt_started', '', -1, '', '']
    _trial(tmp_path / 'a', 0, 8, 60.1, [start, [2.8, 'picked', 'zu12', 1, 'orange', '']])
    _trial(tmp_path / 'b', 0, 7, 62.4, [start, [3.1, 'picked', 'zu12', 1, 'orange', '']])
    assert main([str(tmp_path / 'a'), str(tmp_path / 'b' / 'trial_000'), '--out',
                 str(tmp_path / 'cmp')]) == 0
    text = (tmp_path / 'cmp' / 'comparison.md').read_text()
    assert '| completion time [s] | 60.100 | 62.400 |' in text
    assert 'They differ in: status, completion_time, grasp_successes' in text
    assert ('Where they part: event 1: [2.8 s] zu12 picked orange material 1 in A, [3.1 s] '
            'zu12 picked orange material 1 in B.') in text
    for png in ('timelines.png', 'paths.png'):
        assert (tmp_path / 'cmp' / png).stat().st_size > 5000
    assert 'Where they part' in capsys.readouterr().out
    assert main([str(tmp_path / 'a'), str(tmp_path / 'a'), '--out', str(tmp_path / 'c2')]) == 0
    assert 'They differ in: nothing (the same run).' in \
        (tmp_path / 'c2' / 'comparison.md').read_text()


def test_two_campaigns_with_their_statistics(tmp_path):
    for k in range(10):
        _trial(tmp_path / 'a', k, 8, 60.0 + k % 3, [])
        _trial(tmp_path / 'b', k, 8 if k < 3 else 5, 70.0 + k % 3, [])
    assert len(load_runs(tmp_path / 'a')) == 10
    assert main([str(tmp_path / 'a'), str(tmp_path / 'b'), '--out', str(tmp_path / 'cmp')]) == 0
    text = (tmp_path / 'cmp' / 'comparison.md').read_text()
    assert 'A: ' in text and '(10 trials)' in text
    handling = next(line for line in text.splitlines() if line.startswith('| handling'))
    assert '| 100.0 [95, 100] | 73.8 [63, 82] | -26.2 |' in handling
    assert handling.endswith('| significant |')
    identification = next(line for line in text.splitlines()
                          if line.startswith('| identification'))
    assert not identification.endswith('| significant |')
    assert 'Completed runs: A 10 of 10, B 3 of 10.' in text


def test_what_cannot_be_compared_is_said(tmp_path, capsys):
    _trial(tmp_path / 'a', 0, 8, 60.0, [])
    for k in range(2):
        _trial(tmp_path / 'many', k, 8, 60.0, [])
    assert main([str(tmp_path / 'a'), str(tmp_path / 'many'), '--out', str(tmp_path / 'x')]) == 2
    assert 'a run with a run, or a campaign with a campaign' in capsys.readouterr().err
    assert main([str(tmp_path / 'a'), str(tmp_path / 'nothing')]) == 2
    assert 'nothing does not exist' in capsys.readouterr().err
    (tmp_path / 'empty').mkdir()
    assert main([str(tmp_path / 'a'), str(tmp_path / 'empty')]) == 2
    assert 'no trial result' in capsys.readouterr().err
