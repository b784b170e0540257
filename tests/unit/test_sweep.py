"""Sweeps (studies/sweep.py, run_trials --sweep): the points, their worlds, the plan with
the same seeds at every point, the Wilson intervals and the breaking point, and a sweep run
end to end by the trial runner (trials faked: each point's rates set by its parameter)."""
import csv
import json
import math

import pytest
import yaml

from studies.campaign import CampaignError, check_plan
from studies.sweep import (
    Axis,
    SweepError,
    breaking_point,
    grid,
    parse_axis,
    point_world,
    summarise,
    wilson,
    world_overrides,
)
from trial_record.result import RunInfo, TrialResult
from world_description.world_config import load_world


def test_an_axis_is_a_range_or_a_list():
    assert parse_axis('belt_speed=0.05:0.35:0.05') == Axis(
        'belt_speed', (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35))
    assert parse_axis('perturbations.camera.pixel_noise=0,2.5,8') == Axis(
        'perturbations.camera.pixel_noise', (0.0, 2.5, 8.0))
    assert parse_axis('x=1:1:1') == Axis('x', (1.0,))
    assert parse_axis('cell.youbots=1:3') == Axis('cell.youbots', (1.0, 2.0, 3.0))
    for bad in ('belt_speed', '=1,2', 'a..b=1', 'x=1:0:1', 'x=0:1:0', 'x=0:1:nan', 'x=1,two',
                'x=0:1000:1', '9x=1', 'x=3:1', 'x=1:2:3:4', 'x=0:1000'):
        with pytest.raises(SweepError):
            parse_axis(bad)


def test_two_axes_make_a_grid():
    points = grid([Axis('a', (1.0, 2.0)), Axis('b', (10.0, 20.0, 30.0))])
    assert points[:4] == [{'a': 1.0, 'b': 10.0}, {'a': 1.0, 'b': 20.0}, {'a': 1.0, 'b': 30.0},
                          {'a': 2.0, 'b': 10.0}]
    assert len(points) == 6
    with pytest.raises(SweepError):
        grid([Axis('a', (1.0,)), Axis('a', (2.0,))])
    with pytest.raises(SweepError):
        grid([Axis('a', (1.0,))] * 3)


def test_a_points_world_extends_the_cell_with_its_values(tmp_path):
    point = {'belt_speed': 0.2, 'perturbations.camera.pixel_noise': 5.0,
             'materials.mass': 0.3}
    assert world_overrides(point) == {'perturbations': {'camera': {'pixel_noise': 5.0}},
                                      'materials': {'mass': 0.3}}
    base = 'package://world_description/worlds/pipeline_cell.yaml'
    assert point_world(base, {'belt_speed': 0.2}, tmp_path) == base      # nothing to write
    path = point_world(base, point, tmp_path / 'trial_003')
    world = load_world(path)
    assert world.perturbations.camera.pixel_noise == 5.0
    assert world.materials.mass == 0.3 and world.materials.total == 8      # the rest: the cell's
    assert yaml.safe_load(open(path))['extends'].endswith('pipeline_cell.yaml')
    for bad in ({'perturbations.camera.pixel_nois': 1.0}, {'materials.mass': -1.0},
                {'conveyor.belt_speed.x': 1.0}):
        with pytest.raises(SweepError, match='gives no valid world'):
            point_world(base, bad, tmp_path / 'bad')


def test_wilson_intervals():
    lo, hi = wilson(8, 10)
    assert (round(lo, 3), round(hi, 3)) == (0.49, 0.943)
    assert wilson(10, 10)[1] == 1.0 and wilson(10, 10)[0] == pytest.approx(0.7225, abs=1e-4)
    assert wilson(0, 10)[0] == 0.0
    assert all(math.isnan(v) for v in wilson(0, 0))
    # Narrower with more trials, always around the estimate.
    assert wilson(80, 100)[1] - wilson(80, 100)[0] < hi - lo
    assert wilson(80, 100)[0] < 0.8 < wilson(80, 100)[1]


def _result(trial, speed, handled, total=8, status=None, time=60.0):
    return TrialResult(status or ('completed' if handled == total else 'incomplete'),
                       time, scenario_seed=trial, belt_speed=speed, total=total,
                       identified_correct=total, handled_verified=handled,
                       grasp_attempts=total, grasp_successes=handled,
                       parameters={'belt_speed': speed}, run=RunInfo(trial=trial))


def test_points_are_summarised_and_the_breaking_point_named():
    results = ([_result(k, 0.1, 8) for k in range(3)] + [_result(k, 0.2, 8) for k in range(3)]
               + [_result(k, 0.3, 6) for k in range(3)] + [_result(9, 0.3, 0, status='error')])
    rows = summarise(results)
    assert [r.point for r in rows] == [(('belt_speed', 0.1),), (('belt_speed', 0.2),),
                                       (('belt_speed', 0.3),)]
    assert [r.trials for r in rows] == [3, 3, 3]                       # (the error left out)
    assert rows[2].rates['handling'][0] == pytest.approx(18 / 24)
    assert rows[2].rates['handling'][1:] == pytest.approx(wilson(18, 24))
    assert rows[0].median_time == 60.0 and math.isnan(rows[2].median_time)
    assert breaking_point(rows, 'handling', 0.9) == (('belt_speed', 0.3),)
    assert breaking_point(rows, 'identification', 0.9) is None
    assert summarise([TrialResult('completed', 60.0, run=RunInfo(trial=0))]) == []  # no sweep


def test_a_sweeps_plan_options_are_checked():
    assert check_plan({'sweep': ['belt_speed=0.05:0.3:0.05'], 'trials_per_point': 4},
                      'x')['sweep'] == ['belt_speed=0.05:0.3:0.05']
    for plan, says in [({'sweep': 'belt_speed=0.1'}, 'one or two NAME=VALUES'),
                       ({'sweep': ['belt_speed=0.1:0.9:0.1']}, 'belt speeds within'),
                       ({'sweep': ['x=1', 'y=2', 'z=3']}, 'one or two'),
                       ({'sweep': ['x=one']}, 'finite numbers'),
                       ({'sweep': ['x=1'], 'seeds': [1, 2]}, 'not --seeds'),
                       ({'trials_per_point': 0}, 'trials_per_point must be'),
                       ({'break_below': 1.5}, 'break_below must be')]:
        with pytest.raises(CampaignError) as err:
            check_plan(plan, 'the command line')
        assert says in str(err.value), (plan, str(err.value))


@pytest.mark.slow
def test_a_sweep_runs_every_point_with_the_same_seeds_and_reports_where_it_breaks(
        tmp_path, monkeypatch):
    import studies.run_trials as trials
    import studies.trial_process as trial_run
    from studies.sweep import point_world
    from studies.trial_process import scenario
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')
    ran = []

    def fake_trial(trial, seed, belt_speed, domain_id, out_dir, wall_timeout, record, code,
                   world, time_step, parameters):
        ran.append((trial, seed, belt_speed, dict(parameters)))
        noise = parameters['perturbations.camera.pixel_noise']
        handled = 8 if noise < 10 else 8 - trial % 3 - 1         # fails from noise 10 on
        result = TrialResult('completed' if handled == 8 else 'incomplete', 60.0 + noise,
                             scenario_seed=seed, belt_speed=belt_speed, total=8,
                             identified_correct=8, handled_verified=handled, grasp_attempts=8,
                             grasp_successes=8, parameters=dict(parameters),
                             scenario=scenario(point_world(
                                 world, parameters, out_dir / f'trial_{trial:03d}'), time_step),
                             run=RunInfo(trial=trial, wall_time=1.0, code=code))
        result.write(out_dir / f'trial_{trial:03d}' / 'result.json')
        return result
    monkeypatch.setattr(trial_run, 'run_trial', fake_trial)
    out = tmp_path / 'study'
    argv = ['--sweep', 'perturbations.camera.pixel_noise=0:15:5', '--trials-per-point', '3',
            '--seed0', '11', '--out', str(out), '--progress-period', '0.01',
            '--break-below', '0.95']
    assert trials.main(argv) == 1                            # (some trials did not complete)
    assert [r[0] for r in sorted(ran)] == list(range(12))
    seeds = {}
    for trial, seed, speed, point in ran:
        seeds.setdefault(trial % 3, set()).add((seed, speed))
        assert point == {'perturbations.camera.pixel_noise': 5.0 * (trial // 3)}
    assert all(len(s) == 1 for s in seeds.values())          # the same seed at every point
    report = (out / 'report.md').read_text()
    assert '## The sweep' in report and '4 points of perturbations.camera.pixel_noise' in report
    assert '- handling: at perturbations.camera.pixel_noise 10' in report
    assert '- identification: never, over the 4 points' in report
    assert (out / 'sweep_rates.png').stat().st_size > 5000
    assert (out / 'sweep_times.png').stat().st_size > 5000
    with open(out / 'trials.csv') as f:
        rows = list(csv.DictReader(f))
    assert rows[4]['parameters'] == 'perturbations.camera.pixel_noise=5'
    stored = json.loads((out / 'campaign.json').read_text())['plan']
    assert stored['sweep'] == ['perturbations.camera.pixel_noise=0:15:5']
    # --resume: every trial of the plan is there, made by this code: nothing runs again.
    ran.clear()
    assert trials.main(['--resume', str(out), '--progress-period', '0.01']) == 1
    assert ran == []


def test_a_sweep_over_a_world_value_the_cell_refuses_stops_before_any_trial(tmp_path, capsys):
    import studies.run_trials as trials
    out = tmp_path / 'study'
    assert trials.main(['--sweep', 'materials.mass=0.1,-1', '--out', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'gives no valid world' in err and 'materials.mass must be finite' in err
    assert not list(out.glob('trial_*'))


def test_a_belt_speed_sweeps_report_says_the_belt_was_swept(tmp_path):
    from studies.report import write_report
    result = TrialResult('completed', 60.0, scenario_seed=1, belt_speed=0.2, total=8,
                         parameters={'belt_speed': 0.2}, run=RunInfo(trial=0, code='x'))
    setup = {'seed0': 1, 'belt_speed': (0.1, 0.16), 'parallel': 1}
    text = write_report([result], tmp_path, {**setup, 'sweep': ['belt_speed=0.1:0.3:0.1']})
    assert 'belt speed swept,' in text.read_text() and '(0.1, 0.16)' not in text.read_text()
    text = write_report([result], tmp_path, {**setup, 'sweep': ['perturbations.x=0,1']})
    assert 'belt speed (0.1, 0.16) m/s,' in text.read_text()
