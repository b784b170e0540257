"""run_trials before it starts anything: every input it reads (its options, the world, the
campaign's stored plan and results) is checked, and a bad one is one line and exit code 2,
never a traceback, and never a campaign started on it."""
import json

import pytest

import studies.run_trials as trials
import studies.trial_process as trial_run
from studies.campaign import (
    PLAN_DEFAULTS,
    CampaignError,
    campaign_lock,
    check_plan,
    read_campaign,
    trial_results,
)
from studies.plan import trial_plan
from studies.trial_process import scenario
from trial_record.result import ResultError, RunInfo, TrialResult

WORLD_LINE = 'run_trials: error: --world'


@pytest.fixture
def nothing_runs(monkeypatch):
    """Fails the test if a trial is started."""
    def no_trial(*args, **kwargs):
        raise AssertionError('a trial was started')
    monkeypatch.setattr(trial_run, 'run_trial', no_trial)
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')


def refused(capsys, argv, fragment):
    with pytest.raises(SystemExit) as exit_info:
        code = trials.main(argv)
        raise SystemExit(code)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert exit_info.value.code == 2, err
    assert len(lines) == 1 and lines[0].startswith('run_trials: error:'), err
    assert fragment in lines[0], err
    assert 'Traceback' not in err


@pytest.mark.parametrize('argv, fragment', [
    (['--first-trial', '-5'], 'first_trial must be an integer >= 0'),
    (['--wall-timeout', '-5'], '--wall-timeout must be'),
    (['--wall-timeout', 'nan'], '--wall-timeout must be'),
    (['--progress-period', '0'], '--progress-period must be'),
    (['--trials', '0'], 'trials must be an integer within'),
    (['--parallel', '0'], '--parallel must be >= 1'),
    (['--seeds', '-1'], 'seeds must be a list of integers'),
    (['--seeds', str(2 ** 31)], 'seeds must be a list of integers'),
    (['--belt-speed', '0.2', '0.1'], 'belt_speed must be'),
    (['--belt-speed', 'inf', 'inf'], 'belt_speed must be'),
    (['--time-step', '1'], 'time_step must be within'),
    (['--trials', 'abc'], 'invalid int value'),
    (['--domain-base', '300'], '--domain-base must be'),
])
def test_bad_options_are_one_line(capsys, tmp_path, nothing_runs, argv, fragment):
    refused(capsys, argv + ['--out', str(tmp_path / 'campaign')], fragment)
    assert not (tmp_path / 'campaign').exists()


def world_cases(tmp_path):
    (tmp_path / 'a_directory').mkdir()
    (tmp_path / 'loop_a.yaml').symlink_to(tmp_path / 'loop_b.yaml')
    (tmp_path / 'loop_b.yaml').symlink_to(tmp_path / 'loop_a.yaml')
    files = {'empty.yaml': '{}\n', 'types.yaml': 'robots: 5\n', 'keys.yaml': 'robotz: []\n',
             'not_yaml.yaml': 'robots: [\n', 'deep.yaml': '[' * 5000 + ']' * 5000 + '\n'}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    with open(tmp_path / 'huge.yaml', 'w') as f:           # (a 40 MB world)
        f.write('obstacles:\n')
        for k in range(400_000):
            f.write(f'  - {{shape: box, size: [1, 1, 1], position: [{k}, 0, 0]}}\n')
    return [
        (str(tmp_path / 'missing.yaml'), 'does not exist'),
        (str(tmp_path / 'a_directory'), 'is a directory'),
        (str(tmp_path / 'loop_a.yaml'), 'Too many levels of symbolic links'),
        ('package://no_such_package/worlds/x.yaml', 'not found in the ament index'),
        (str(tmp_path / 'empty.yaml'), 'no conveyor'),
        (str(tmp_path / 'types.yaml'), 'must be a list'),
        (str(tmp_path / 'keys.yaml'), 'robotz'),
        (str(tmp_path / 'not_yaml.yaml'), 'not valid YAML'),
        (str(tmp_path / 'deep.yaml'), 'world'),
        (str(tmp_path / 'huge.yaml'), 'a world file is at most'),
    ]


@pytest.mark.slow
def test_a_bad_world_is_one_line_before_anything_starts(capsys, tmp_path, nothing_runs):
    for world, fragment in world_cases(tmp_path):
        out = tmp_path / 'campaign'
        refused(capsys, ['--world', world, '--out', str(out)], fragment)
        assert not out.exists(), world
        refused(capsys, ['--world', world, '--show-graph'], fragment)


@pytest.mark.parametrize('stored, fragment', [
    ({'plan': 5}, 'the plan must be a mapping'),
    ('abc', 'a JSON object was expected'),
    ([], 'a JSON object was expected'),
    ({'trials': 3}, 'unknown fields'),
    ({'code': 'x'}, 'is not a campaign file'),
    ({'plan': {'trials': 'x'}}, 'trials must be an integer'),
    ({'plan': {'belt_speed': 5}}, 'belt_speed must be'),
    ({'plan': {'seeds': ['a']}}, 'seeds must be a list of integers'),
    ({'plan': {'world': 7}}, 'world must be'),
    ({'plan': {'speed': 1}}, "unknown plan options ['speed']"),
    ({'plan': {'trials': True}}, 'trials must be an integer'),
])
def test_a_damaged_campaign_file_is_one_line(capsys, tmp_path, nothing_runs, stored, fragment):
    (tmp_path / 'campaign.json').write_text(json.dumps(stored))
    refused(capsys, ['--resume', str(tmp_path)], fragment)
    (tmp_path / 'campaign.json').write_text('{"plan": {')
    refused(capsys, ['--resume', str(tmp_path)], 'not JSON')


def test_resume_and_report_need_a_campaign_directory(capsys, tmp_path, nothing_runs):
    refused(capsys, ['--resume', str(tmp_path / 'nonexistent')], 'not a campaign directory')
    assert not (tmp_path / 'nonexistent').exists()
    refused(capsys, ['--report-only', '--out', str(tmp_path / 'nonexistent')],
            'not a campaign directory')


def test_an_out_that_cannot_be_a_directory_is_one_line(capsys, tmp_path, nothing_runs):
    (tmp_path / 'a_file').write_text('')
    refused(capsys, ['--out', str(tmp_path / 'a_file')], '--out')
    refused(capsys, ['--out', str(tmp_path / 'a_file' / 'below')], '--out')


def test_a_new_campaign_does_not_write_over_another(capsys, tmp_path, nothing_runs):
    (tmp_path / 'campaign.json').write_text(json.dumps({'plan': {'trials': 3}}))
    refused(capsys, ['--out', str(tmp_path)], 'holds a campaign already')


def test_a_result_file_that_is_not_a_result(capsys, tmp_path, monkeypatch):
    """A result.json holding [] gave an AttributeError with --resume and --report-only: the
    report names it, and a resumed campaign runs that trial again."""
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')
    plan = trial_plan(2, 0, 7, (0.1, 0.16))
    (tmp_path / 'campaign.json').write_text(json.dumps(
        {'plan': {'trials': 2, 'seed0': 7}, 'code': 'abc123'}))
    ran_as = scenario(PLAN_DEFAULTS['world'], PLAN_DEFAULTS['time_step'])
    for k, content in ((0, []), (1, {'trial': 1, 'scenario_seed': plan[1]['seed'],
                                     'belt_speed': plan[1]['belt_speed'],
                                     'status': 'completed', 'completion_time': 60.0,
                                     'wall_time': 9.0, 'code': 'abc123',
                                     'scenario': ran_as})):
        (tmp_path / f'trial_{k:03d}').mkdir()
        (tmp_path / f'trial_{k:03d}' / 'result.json').write_text(json.dumps(content))
    refused(capsys, ['--report-only', '--out', str(tmp_path)],
            'trial_000/result.json: not a trial result (a JSON list)')
    ran = []

    def fake_trial(trial, seed, belt_speed, domain_id, out_dir, wall_timeout, record, code,
                   world, time_step):
        ran.append(trial)
        return TrialResult('completed', 61.0, scenario_seed=seed, belt_speed=belt_speed,
                           scenario=scenario(world, time_step),
                           run=RunInfo(trial=trial, wall_time=9.0, code=code))
    monkeypatch.setattr(trial_run, 'run_trial', fake_trial)
    import studies.report
    monkeypatch.setattr(studies.report, 'write_report', lambda r, out, s: out / 'report.md')
    assert trials.main(['--resume', str(tmp_path), '--progress-period', '0.01']) == 0
    assert ran == [0]
    assert 'trial 0 runs again' in capsys.readouterr().out


def result_problem(data):
    try:
        TrialResult.from_dict(data)
    except ResultError as exc:
        return str(exc)
    return None


def test_results_are_checked_field_by_field():
    good = {'scenario_seed': 5, 'belt_speed': 0.12, 'status': 'completed',
            'completion_time': float('nan'), 'handling_success_rate': 1.0,
            'run': {'trial': 3, 'wall_time': 9.0, 'code': 'abc'}}
    assert result_problem(good) is None
    # The first layout, with the run's metadata at the top level, reads into the same record.
    flat = {**{k: v for k, v in good.items() if k != 'run'}, **good['run']}
    assert TrialResult.from_dict(flat).run == TrialResult.from_dict(good).run
    for change, fragment in (({'status': 5}, 'status is 5, not a string'),
                             ({'trial': -1}, 'trial is'),
                             ({'run': {'trial': 'x'}}, 'trial is'),
                             ({'scenario_seed': 'a'}, 'scenario_seed is'),
                             ({'belt_speed': None}, 'belt_speed is'),
                             ({'run': {'wall_time': '1'}}, 'wall_time is'),
                             ({'run': {'cpu_seconds': {'sim_node': 'a'}}},
                              'cpu_seconds: sim_node is'),
                             ({'handling_success_rate': 2.0}, 'not a number within 0..1')):
        assert fragment in result_problem({**good, **change})
    assert 'JSON str' in result_problem('abc')


def test_the_plan_is_checked_and_normalised():
    assert check_plan({'belt_speed': (0.1, 0.2)}, 'x')['belt_speed'] == [0.1, 0.2]
    with pytest.raises(CampaignError, match='x: first_trial'):
        check_plan({'first_trial': -1}, 'x')


def test_two_runners_never_share_a_campaign_directory(tmp_path, capsys, nothing_runs):
    """Two campaigns into one --out both exited 0: campaign.json ended with one's plan and
    trials.csv with the other's results."""
    with campaign_lock(tmp_path):
        with pytest.raises(CampaignError, match='in use by another run_trials'):
            with campaign_lock(tmp_path):
                pass
        refused(capsys, ['--out', str(tmp_path)], 'in use by another run_trials (pid ')
    with campaign_lock(tmp_path):                      # (free again)
        pass


def test_trial_results_skip_nothing_silently(tmp_path):
    (tmp_path / 'trial_000').mkdir()
    (tmp_path / 'trial_000' / 'result.json').write_text('{"status": "completed"}')
    (tmp_path / 'trial_001').mkdir()
    (tmp_path / 'trial_001' / 'result.json').write_text('{"status": ')
    results, problems = trial_results(tmp_path)
    assert [r.trial for r in results] == [0]
    assert len(problems) == 1 and 'trial_001/result.json: not JSON' in problems[0]
    assert read_campaign(tmp_path) is None


def test_a_trial_whose_executable_is_gone_fails_alone(tmp_path, monkeypatch):
    """A workspace rebuilt under a running campaign (its executables gone for a moment): the
    trial that could not start its processes was an exception that ended the whole campaign
    (a 110-trial sweep, 56 trials in). It is now a failed trial, and says why."""
    from studies.trial_process import run_trial
    monkeypatch.setenv('PATH', str(tmp_path / 'nothing_here'))
    result = run_trial(3, 11, 0.12, 231, tmp_path, wall_timeout=5.0,
                       parameters={'belt_speed': 0.12})
    assert result.status == 'error' and result.trial == 3
    assert result.message.startswith('cannot start sim_node (sim_node): No such file')
    assert 'source scripts/env.sh' in result.message
    written = json.loads((tmp_path / 'trial_003' / 'result.json').read_text())
    assert written['status'] == 'error' and written['parameters'] == {'belt_speed': 0.12}
    assert 'cannot start sim_node' in (tmp_path / 'trial_003' / 'sim_node.log').read_text()
