"""Scoring a run against ground truth, the trials' summary, CSV and report."""
import csv
import importlib.util
import json
import re
from dataclasses import replace

import cv2
import numpy as np
import pytest

from coordinator.pipeline import RunResult
from studies.campaign import write_csv
from studies.plan import trial_plan
from studies.report import STATE_COLORS, activity, summary_rows, write_report
from trial_record.result import ResultError, RunInfo, TrialResult
from trial_record.scoring import (
    IdentificationCheck,
    at_destination,
    match_identification,
    regions_from_world,
    score,
    tracks_of,
)
from world_description.resources import resolve_resource
from world_description.world_config import load_world

WORLD = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))


def _near(obstacle: str, dx: float, dy: float, z: float) -> np.ndarray:
    """A point at (dx, dy) from a named obstacle's centre of the cell's world, at height z."""
    o = next(o for o in WORLD.obstacles if o.name == obstacle)
    return np.array([o.position[0] + dx, o.position[1] + dy, z])


IN_POOL = _near('pool_floor', -0.2, -0.1, 0.025)          # on the pool's floor
ON_PLATFORM = _near('pool_platform', -0.1, 0.0, 0.175)
BESIDE_PLATFORM = _near('pool_platform', -0.19, 0.2, 0.025)     # on the floor, between the two


@pytest.fixture(scope='module')
def regions():
    return regions_from_world(WORLD)


def test_destinations_by_the_worlds_rules(regions):
    assert at_destination('purple', (-0.5, 0.3, 0.027), regions)
    assert not at_destination('purple', (-0.5, 0.0, 0.027), regions)     # beside the target
    assert not at_destination('purple', (-0.5, 0.3, 0.077), regions)     # on another one
    assert at_destination('orange', IN_POOL, regions)
    assert not at_destination('orange', IN_POOL + [0, 0, 0.05], regions)   # on another one
    assert not at_destination('orange', IN_POOL + [0, 0, 0.1], regions)    # on the wall top
    assert not at_destination('green', IN_POOL, regions)                   # no class of the cell
    assert at_destination('blue', ON_PLATFORM, regions)
    assert not at_destination('blue', BESIDE_PLATFORM, regions)           # fell off it
    assert not at_destination('orange', (1.0, 0.75, 0.425), regions)       # still on the belt


def test_identifications_are_matched_to_the_nearest_true_material():
    truth = [('orange', np.array([-0.5, 0.75, 0.425])), ('blue', np.array([-0.8, 0.75, 0.425]))]
    assert match_identification((-0.51, 0.752, 0.425), truth) == 'orange'
    assert match_identification((-0.79, 0.75, 0.425), truth) == 'blue'
    assert match_identification((-0.65, 0.75, 0.425), truth) is None        # nothing within 4 cm


def _result(**kw):
    base = dict(status='completed', completion_time=139.0, total=8, identified=8, picked=8,
                delivered=8, grasp_attempts=16, grasp_successes=15, missed=0, failed=0)
    base.update(kw)
    return RunResult(**base)


def test_score_takes_handling_from_ground_truth_not_from_the_coordinator(regions):
    truth = [('orange', IN_POOL)] * 6 + [
        ('purple', np.array([-0.5, 0.3, 0.027])), ('blue', BESIDE_PLATFORM)]
    out = score(_result(), truth, [True] * 7 + [False], regions)
    assert out.delivered == 8                       # what the coordinator believed
    assert out.handled_verified == 7 and out.handling_success_rate == 7 / 8
    assert out.identification_rate == 7 / 8
    assert out.grasp_success_rate == 15 / 16


def test_the_rates_split_as_the_paper_splits_them(regions):
    # The Zu 12 picked 8 in 9 attempts; the youBot unloaded in 7 of 8; of the 7 materials on
    # its plate one orange ended outside the pool.
    r = _result(loader_grasp_attempts=9, loader_grasp_successes=8, transport_grasp_attempts=8,
                transport_grasp_successes=7, loaded=7)
    truth = ([('purple', np.array([-0.5, 0.3, 0.027])), ('blue', ON_PLATFORM)]
             + [('orange', IN_POOL + [0.01 * k, 0, 0.0]) for k in range(5)]
             + [('orange', np.array([1.0, 0.0, 0.025]))])
    out = score(r, truth, [True] * 8, regions)
    assert out.loader_grasp_rate == pytest.approx(8 / 9)
    assert out.transport_grasp_rate == pytest.approx(7 / 8)
    assert out.transport_rate == pytest.approx(6 / 7)
    assert out.handling_success_rate == pytest.approx(7 / 8)
    # Nothing loaded: no transport to rate, not a division by zero.
    assert score(_result(), truth, [True] * 8, regions).transport_rate == 0.0


def test_results_name_roles_and_robots_and_read_the_records_that_named_the_models():
    """The grasps per role (the paper's split: its Zu 12 was the loader, its youBot the
    transport) and per robot; a record written before, with the models' names, reads as the
    roles'; a record that has both, or a robot with more successes than attempts, or a role
    the cell has not, is refused naming the field."""
    old = {'status': 'completed', 'zu12_grasp_attempts': 9, 'zu12_grasp_successes': 8,
           'youbot_grasp_attempts': 7, 'youbot_grasp_successes': 7, 'zu12_grasp_rate': 8 / 9,
           'youbot_grasp_rate': 1.0}
    r = TrialResult.from_dict(old)
    assert (r.loader_grasp_attempts, r.loader_grasp_successes, r.loader_grasp_rate) == (
        9, 8, 8 / 9)
    assert (r.transport_grasp_attempts, r.transport_grasp_rate) == (7, 1.0)
    assert r.robot_grasps is None and 'robot_grasps' not in r.to_dict()
    with pytest.raises(ResultError, match='has both zu12_grasp_attempts and '
                                          'loader_grasp_attempts'):
        TrialResult.from_dict({**old, 'loader_grasp_attempts': 9})
    mine = {'arm': {'role': 'loader', 'attempts': 9, 'successes': 8},
            'carrier': {'role': 'transport', 'attempts': 7, 'successes': 7}}
    back = TrialResult.from_dict(json.loads(replace(r, robot_grasps=mine).to_json()))
    assert back.robot_grasps == mine
    for bad, fragment in (({'role': 'loader', 'attempts': 1, 'successes': 2}, 'more than its'),
                          ({'role': 'welder', 'attempts': 1, 'successes': 1}, 'role'),
                          ({'role': 'loader', 'attempts': 1}, 'successes')):
        with pytest.raises(ResultError, match=fragment):
            TrialResult.from_dict({'status': 'completed', 'robot_grasps': {'arm': bad}})


def test_the_peak_joint_speed_is_the_largest_fraction_of_any_joints_limit():
    from trial_record.scoring import PeakJointSpeed
    peak = PeakJointSpeed([2.0, 3.0, 1.0])
    peak.update([1.0, -2.7, 0.5])                      # joint 1 at 0.9 of its limit
    peak.update([0.1, 0.1, float('nan')])              # a bad sample is ignored
    peak.update([0.5, 0.5])                            # so is one of the wrong size
    assert peak.fraction == pytest.approx(0.9) and peak.joint == 1
    peak.update([0.0, 0.0, -1.02], 12.5)               # over the limit: shown, not hidden
    assert peak.fraction == pytest.approx(1.02) and peak.joint == 2 and peak.time == 12.5


def test_summary_and_report(tmp_path):
    trials = []
    for k, (t, handling) in enumerate([(130.0, 1.0), (140.0, 0.875), (150.0, 1.0)]):
        trials.append({'trial': k, 'scenario_seed': 10 + k, 'belt_speed': 0.12,
                       'status': 'completed' if handling == 1.0 else 'incomplete',
                       'completion_time': t, 'identification_rate': 1.0,
                       'grasp_success_rate': 1.0, 'handling_success_rate': handling,
                       'youbot_path': [[0.6, -0.55], [1.7, -1.7], [0.6, -0.55]],
                       'materials': [{'id': 3, 'color': 'blue', 'status': 'failed',
                                      'failure': 'not held after 2 attempts'}]
                       if handling < 1.0 else [], 'wall_time': 80.0})
    # (Robots as a world names them: the summary has a peak for each name any trial has.)
    trials[0]['peak_joint_speed'] = {'arm': {'fraction_of_limit': 0.9, 'joint': 'joint_1',
                                             'time': 3.0}}
    trials[1]['peak_joint_speed'] = {'arm': {'fraction_of_limit': 0.97, 'joint': 'joint_2',
                                             'time': 4.0},
                                     'carrier': {'fraction_of_limit': 1.0,
                                                 'joint': 'arm_joint_1', 'time': 9.0}}
    trials[2]['joints_driven_past'] = [{'robot': 'youbot', 'joint': 'arm_joint_4',
                                        'ratio': 1.31, 'speed': 2.06, 'limit': 1.5708,
                                        'brake': 2.7, 'time': 40.0, 'count': 1}]
    trials = [TrialResult.from_dict(t) for t in trials]
    s = summary_rows(trials)
    assert s['median_completion_time'] == 140.0 and s['completed'] == 2
    assert s['handling_success_rate'] == pytest.approx((2 + 0.875) / 3)
    report = write_report(trials, tmp_path, {'note': 'three trials'}).read_text()
    assert '| **these trials** | 3 | 140.0' in report
    assert '| paper, trials 100-110 | | 61 | 99 | 99 | 10 |' in report
    assert 'trial 1 (seed 11, belt 0.120): incomplete' in report and 'blue 3' in report
    assert s['trials_joints_driven_past'] == 1 and s['worst_driven_past'] == 1.31
    assert (s['peak_joint_speed_arm'], s['peak_joint_speed_carrier']) == (0.97, 1.0)
    assert 'fraction of each joint\'s published limit): arm 0.970, carrier 1.000;' in report
    assert ('The world drove a joint past its limit (braked back to it) in 1 trials, at worst '
            '1.31 times its limit') in report
    for png in ('completion_times.png', 'success_rates.png', 'youbot_paths.png'):
        assert (tmp_path / png).stat().st_size > 1000
    write_csv(trials, tmp_path / 'trials.csv')
    rows = list(csv.DictReader(open(tmp_path / 'trials.csv')))
    assert [r['trial'] for r in rows] == ['0', '1', '2'] and rows[1]['status'] == 'incomplete'


def test_the_report_draws_each_robots_activity_over_the_median_trial(tmp_path):
    """The timeline: a lane for the belt, the loader (by its robot's name) and the youBot, a
    bar per state, drawn for the trial of median completion time, from the state changes its
    result lists."""
    trials = []
    for k, end in enumerate((70.0, 60.0, 80.0)):
        trials.append({
            'robot_grasps': {'panda': {'role': 'loader', 'attempts': 9, 'successes': 8},
                             'youbot': {'role': 'transport', 'attempts': 7, 'successes': 7}},
            'trial': k, 'scenario_seed': k, 'belt_speed': 0.12, 'status': 'completed',
            'completion_time': end, 'identification_rate': 1.0, 'grasp_success_rate': 1.0,
            'handling_success_rate': 1.0, 'youbot_path': [], 'materials': [],
            'events': [[0.0, 'belt_started', '', -1, '', ''],
                       [30.0, 'belt_stopped', '', -1, '', '']],
            'states': [[0.0, 'loader', 'wait'], [2.0, 'loader', 'pick'],
                       [5.0, 'loader', 'place'], [30.0, 'loader', 'home'],
                       [33.0, 'loader', 'done'], [0.0, 'transport', 'wait_load'],
                       [31.0, 'transport', 'drive'], [40.0, 'transport', 'grasp'],
                       [end - 5.0, 'transport', 'drive'], [end - 1.0, 'transport', 'fold'],
                       [end, 'transport', 'done']]})
    trials = [TrialResult.from_dict(t) for t in trials]
    lanes = activity(trials[0])
    assert lanes['belt'] == [(0.0, 30.0, 'running')]
    assert lanes['panda'][-1] == (30.0, 33.0, 'home')         # nothing drawn once done
    assert lanes['youBot'][1] == (31.0, 40.0, 'drive')
    report = write_report(trials, tmp_path, {'note': 'three trials'}).read_text()
    assert '![timeline](timeline.png)' in report
    assert ('panda (loader) 24 of 27 (88.9 %); youbot (transport) 21 of 21 (100.0 %).'
            in report)
    # (A record from before robots were told apart: its loader's lane is the role's.)
    trials[0].robot_grasps = None
    assert activity(trials[0])['loader'][-1] == (30.0, 33.0, 'home')
    img = cv2.imread(str(tmp_path / 'timeline.png'))
    assert img is not None

    def at(lane: int, t: float, end: float = 70.0):      # the median trial: 70 s
        return tuple(int(v) for v in img[50 + lane * 60 + 25, int(90 + 780 * t / end)])
    assert at(0, 10.0) == STATE_COLORS['running'] and at(0, 50.0) == (255, 255, 255)
    assert at(1, 3.0) == STATE_COLORS['pick'] and at(1, 20.0) == STATE_COLORS['place']
    assert at(1, 50.0) == (255, 255, 255)
    assert at(2, 35.0) == STATE_COLORS['drive'] and at(2, 50.0) == STATE_COLORS['grasp']
    assert at(2, 67.0) == STATE_COLORS['drive']


def test_a_fleets_report_has_a_lane_a_path_and_a_row_per_youbot(tmp_path):
    """With several youBots the timeline has a lane per youBot (its machine is its robot's
    name), the paths map draws every youBot's path, and a table gives each one's share."""
    from studies.report import youbot_paths

    def share(trips, path):
        return {'trips': trips, 'carried': 4 * trips, 'delivered': 4 * trips, 'distance': 9.5,
                'busy': 40.0, 'waiting': 20.0, 'path': path}
    trials = [TrialResult.from_dict({
        'trial': k, 'status': 'completed', 'completion_time': 60.0 + k, 'youbot_path': [],
        'transports': {'alpha': share(1 + k, [[0.0, 0.0], [1.0, 0.0]]),
                       'beta': share(2, [[0.0, 1.0], [1.0, 1.0]])},
        'closest_bases': {'distance': 0.25 - 0.01 * k, 'time': 3.0, 'robots': ['alpha', 'beta']},
        'states': [[0.0, 'loader', 'wait'], [0.0, 'alpha', 'wait_load'],
                   [10.0, 'alpha', 'drive'], [0.0, 'beta', 'wait_bay'],
                   [20.0, 'beta', 'drive'], [50.0, 'beta', 'done']]}) for k in range(3)]
    lanes = activity(trials[0])
    assert set(lanes) == {'belt', 'loader', 'alpha', 'beta'}
    assert lanes['beta'] == [(0.0, 20.0, 'wait_bay'), (20.0, 50.0, 'drive')]
    # Before its first change of state a youBot waits at its park.
    trials[1].states[1:3] = [[5.0, 'alpha', 'wait_load'], [10.0, 'alpha', 'drive']]
    assert activity(trials[1])['alpha'][0] == (0.0, 5.0, 'wait_bay')
    assert list(youbot_paths(trials)) == ['trial 0 alpha', 'trial 0 beta', 'trial 1 alpha',
                                          'trial 1 beta', 'trial 2 alpha', 'trial 2 beta']
    assert len(youbot_paths(trials, most=5)) == 4          # (a trial's robots all or none)
    report = write_report(trials, tmp_path, {'note': 'a fleet'}).read_text()
    assert '| alpha | 2.0 | 8.0 | 8.0 | 9.5 | 40.0 | 20.0 |' in report
    assert '| beta | 2.0 | 8.0 |' in report
    assert 'no nearer than 0.230 m' in report
    img = cv2.imread(str(tmp_path / 'timeline.png'))
    assert img.shape[0] == 150 + 60 * 4
    y = 50 + 3 * 60 + 25                                      # beta's lane, trial 1 (61 s)
    assert tuple(int(v) for v in img[y, int(90 + 780 * 30.0 / 61.0)]) == STATE_COLORS['drive']


def test_a_trial_plan_is_reproducible_and_splits_over_machines():
    whole = trial_plan(10, 0, 2026, (0.1, 0.16))
    assert whole == trial_plan(10, 0, 2026, (0.1, 0.16))
    assert trial_plan(4, 6, 2026, (0.1, 0.16)) == whole[6:]
    assert all(0.1 <= t['belt_speed'] <= 0.16 for t in whole)
    assert len({t['seed'] for t in whole}) == 10


def test_an_interrupted_campaign_goes_on_where_it_stopped(tmp_path, monkeypatch):
    import studies.report
    import studies.run_trials as trials
    import studies.trial_process as trial_run
    from studies.campaign import PLAN_DEFAULTS
    from studies.trial_process import scenario
    plan = trial_plan(4, 0, 7, (0.1, 0.16))
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')
    (tmp_path / 'campaign.json').write_text(json.dumps(
        {'plan': {'trials': 4, 'seed0': 7}, 'code': 'abc123'}))
    ran_as = scenario(PLAN_DEFAULTS['world'], PLAN_DEFAULTS['time_step'])
    # Trial 0 of this plan finished before the interruption; trial 1's result is of another
    # plan (another seed), trial 2 was stopped by the interruption, and trial 3 was run by
    # other code: those three run again.
    for k, seed, status, code in ((0, plan[0]['seed'], 'completed', 'abc123'),
                                  (1, plan[1]['seed'] + 1, 'completed', 'abc123'),
                                  (2, plan[2]['seed'], 'interrupted', 'abc123'),
                                  (3, plan[3]['seed'], 'completed', 'abc123-dirty')):
        (tmp_path / f'trial_{k:03d}').mkdir()
        (tmp_path / f'trial_{k:03d}' / 'result.json').write_text(json.dumps({
            'trial': k, 'scenario_seed': seed, 'belt_speed': plan[k]['belt_speed'],
            'status': status, 'completion_time': 60.0, 'wall_time': 100.0, 'code': code,
            'scenario': ran_as}))
    ran = []

    def fake_trial(trial, seed, belt_speed, domain_id, out_dir, wall_timeout, record, code,
                   world, time_step):
        assert code == 'abc123'
        ran.append(trial)
        return TrialResult('completed', 61.0, scenario_seed=seed, belt_speed=belt_speed,
                           run=RunInfo(trial=trial, wall_time=90.0, code=code))
    reported = []
    monkeypatch.setattr(trial_run, 'run_trial', fake_trial)
    monkeypatch.setattr(studies.report, 'write_report',
                        lambda results, out, meta: reported.append(results) or out / 'report.md')
    assert trials.main(['--trials', '4', '--seed0', '7', '--resume', '--out', str(tmp_path),
                        '--progress-period', '0.01']) == 0
    assert sorted(ran) == [1, 2, 3]
    assert sorted(r.trial for r in reported[0]) == [0, 1, 2, 3]
    with open(tmp_path / 'trials.csv') as f:
        assert [row['trial'] for row in csv.DictReader(f)] == ['0', '1', '2', '3']


def test_a_campaign_stopped_by_the_user_keeps_a_report_and_resumes_with_its_plan(
        tmp_path, monkeypatch):
    """Ctrl-C: the running trial is stopped, the finished ones are in the CSV and the report;
    ``--resume DIR`` alone goes on with the same plan, and a plan option that differs from it
    is refused."""
    import studies.run_trials as trials
    import studies.trial_process as trial_run
    from studies.trial_process import scenario
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')
    ran, reports = [], []

    def fake_trial(trial, seed, belt_speed, domain_id, out_dir, wall_timeout, record, code,
                   world, time_step):
        if trial == 1 and not ran.count(1):
            ran.append(1)
            raise KeyboardInterrupt          # (the user's Ctrl-C, as the pool passes it on)
        ran.append(trial)
        result = TrialResult('completed', 60.0, scenario_seed=seed, belt_speed=belt_speed,
                             scenario=scenario(world, time_step),
                             run=RunInfo(trial=trial, wall_time=90.0, code=code))
        result.write(out_dir / f'trial_{trial:03d}' / 'result.json')
        return result
    monkeypatch.setattr(trial_run, 'run_trial', fake_trial)
    import studies.pool
    monkeypatch.setattr(studies.pool, 'stop_all', lambda: trial_run.INTERRUPTED.set())
    import studies.report
    monkeypatch.setattr(studies.report, 'write_report',
                        lambda results, out, setup: reports.append((results, setup))
                        or out / 'report.md')
    out = tmp_path / 'campaign'
    assert trials.main(['--trials', '3', '--seed0', '7', '--belt-speed', '0.11', '0.15',
                        '--out', str(out), '--progress-period', '0.01']) == 130
    with open(out / 'trials.csv') as f:
        assert [row['trial'] for row in csv.DictReader(f)] == ['0']
    results, setup = reports[-1]
    assert [r.trial for r in results] == [0] and 'Interrupted: 1 of the 3' in setup['note']
    assert trials.main(['--resume', str(out), '--trials', '4']) == 2     # (not its plan)
    assert trials.main(['--resume', str(out), '--progress-period', '0.01']) == 0
    assert ran == [0, 1, 1, 2]
    results, setup = reports[-1]
    plan = trial_plan(3, 0, 7, (0.11, 0.15))
    assert [(r.trial, r.scenario_seed, r.belt_speed) for r in
            sorted(results, key=lambda r: r.trial)] == [
        (p['trial'], p['seed'], p['belt_speed']) for p in plan]
    assert 'note' not in setup


def test_trials_on_one_machine_never_share_a_dds_domain(tmp_path, monkeypatch):
    """A lease is the first domain from the base that no other holder has, across processes,
    and comes free when its holder ends (even a killed one)."""
    import subprocess
    import sys

    import studies.trial_process as trial_run
    monkeypatch.setattr(trial_run, 'DOMAIN_LOCK_DIR', tmp_path)
    with trial_run.domain_lease(150) as first, trial_run.domain_lease(150) as second:
        assert (first, second) == (150, 151)
        holder = subprocess.Popen([sys.executable, '-c', (
            'import sys, time, studies.trial_process as t, pathlib\n'
            f't.DOMAIN_LOCK_DIR = pathlib.Path({str(tmp_path)!r})\n'
            'with t.domain_lease(150) as d:\n'
            '    print(d, flush=True); time.sleep(60)')], stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == '152'
            with trial_run.domain_lease(150) as fourth:
                assert fourth == 153
        finally:
            holder.kill()
            holder.wait()
        with trial_run.domain_lease(150) as freed:         # the killed holder's domain
            assert freed == 152
    with trial_run.domain_lease(150) as again:
        assert again == 150
    with trial_run.domain_lease(trial_run.MAX_DOMAIN) as last:
        with pytest.raises(RuntimeError, match='no free DDS domain'):
            with trial_run.domain_lease(last):
                pass


def test_the_code_version_names_the_commit_and_uncommitted_code_changes(tmp_path, monkeypatch):
    import shutil
    import subprocess
    import sys

    import trial_record.result as trial_result
    if shutil.which('git') is None:
        pytest.skip('git is not installed')
    repo = tmp_path / 'repo'
    (repo / 'pkg').mkdir(parents=True)
    (repo / 'docs').mkdir()
    shutil.copy(trial_result.__file__, repo / 'pkg' / 'trials.py')
    (repo / 'docs' / 'result.json').write_text('{}')

    def git(*args):
        subprocess.run(['git', '-C', str(repo), '-c', 'user.name=t', '-c', 'user.email=t@t',
                        *args], check=True, capture_output=True)
    git('init', '-q')
    git('add', '-A')
    git('commit', '-qm', 'one')
    spec = importlib.util.spec_from_file_location('copied_trials', repo / 'pkg' / 'trials.py')
    copied = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, copied)       # (its dataclasses look it up)
    spec.loader.exec_module(copied)
    commit = copied.code_version()
    assert re.fullmatch(r'[0-9a-f]{12}', commit)
    (repo / 'docs' / 'result.json').write_text('{"status": "completed"}')   # a result: clean
    assert copied.code_version() == commit
    with open(repo / 'pkg' / 'trials.py', 'a') as f:
        f.write('# changed\n')
    assert copied.code_version() == commit + '-dirty'


def test_outside_a_checkout_the_code_version_is_the_one_the_image_was_built_from(
        tmp_path, monkeypatch):
    """A container image has no .git: its build hands the commit over in an environment
    variable (docker/Dockerfile), and without one the version is 'unknown'."""
    import shutil
    import sys

    import trial_record.result as trial_result
    (tmp_path / 'pkg').mkdir()
    shutil.copy(trial_result.__file__, tmp_path / 'pkg' / 'trials.py')
    monkeypatch.setenv('GIT_CEILING_DIRECTORIES', str(tmp_path))   # no checkout above it
    spec = importlib.util.spec_from_file_location('copied_trials2', tmp_path / 'pkg' / 'trials.py')
    copied = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, copied)
    spec.loader.exec_module(copied)
    monkeypatch.delenv('ROBOT_SIM_CODE_VERSION', raising=False)
    assert copied.code_version() == 'unknown'
    monkeypatch.setenv('ROBOT_SIM_CODE_VERSION', '298fa3b1c2d3')
    assert copied.code_version() == '298fa3b1c2d3'


def test_two_runs_differ_only_where_their_outcome_does_not_in_their_metadata():
    one = TrialResult('completed', 60.1, scenario_seed=0, belt_speed=0.12, delivered=8,
                      events=[[1.5, 'picked', 'zu12', 0, 'orange', '']],
                      run=RunInfo(trial=0, wall_time=39.0))
    other = one.with_run(wall_time=43.8, code='abc', cpu_seconds={'sim_node': 27.0})
    assert one.differences(other) == []                 # NaN rates equal NaN
    moved = TrialResult.from_dict({**other.to_dict(), 'completion_time': 60.2,
                                   'events': [[1.6, 'picked', 'zu12', 0, 'orange', '']]})
    assert one.differences(moved) == ['completion_time', 'events']


def test_each_material_not_at_its_destination_says_what_went_wrong():
    from trial_record.scoring import failure_cause

    def seen(truth_id, material, color, true_color):
        return {'truth_id': truth_id, 'material': material, 'color': color,
                'true_color': true_color}
    details = [seen(1, 11, 'orange', 'orange'), seen(2, 12, 'purple', 'orange'),
               seen(3, 13, 'orange', 'orange'), seen(4, 14, 'orange', 'orange'),
               seen(5, 15, 'orange', 'orange'), seen(6, 16, 'purple', 'purple'),
               seen(7, 17, 'orange', 'orange'), seen(8, 18, 'orange', 'orange'),
               seen(9, 19, 'orange', 'orange')]
    materials = [{'id': 11, 'status': 'delivered', 'failure': ''},
                 {'id': 12, 'status': 'placed', 'failure': ''},
                 {'id': 13, 'status': 'missed', 'failure': 'went off the belt end unpicked'},
                 {'id': 14, 'status': 'failed', 'failure': 'grasp: nothing within 4 mm'},
                 {'id': 15, 'status': 'on_plate', 'failure': ''},
                 {'id': 16, 'status': 'seen', 'failure': ''},
                 {'id': 17, 'status': 'picking', 'failure': ''},
                 {'id': 18, 'status': 'delivered', 'failure': ''},
                 {'id': 19, 'status': 'failed', 'failure': 'unreachable'}]
    events = [[2.0, 'picked', 'zu12', 11, 'orange', ''], [3.0, 'grasp_failed', 'zu12', 14,
                                                          'orange', 'grasp: nothing'],
              [4.0, 'picked', 'zu12', 15, 'orange', ''], [5.0, 'loaded', 'zu12', 15, 'orange',
                                                          'plate slot 0'],
              [6.0, 'picked', 'zu12', 17, 'orange', '']]
    where = {8: 'on pool_floor but 0.049 m over its face, on another material, at (2, -1, 0.05)'}
    causes = {k: failure_cause(k, 'purple' if k == 6 else 'orange', details, materials,
                               events, where.get(k, ''))[0] for k in range(10)}
    # (A material left on the plate was said to be lost on the way, never unloaded.)
    assert causes == {0: 'not_seen', 1: 'out_of_place', 2: 'wrong_colour', 3: 'missed',
                      4: 'grasp_missed', 5: 'left_on_plate', 6: 'not_handled', 7: 'dropped',
                      8: 'on_another', 9: 'given_up'}
    assert 'no unload of it was tried' in failure_cause(5, 'orange', details, materials,
                                                        events)[1]
    assert 'on another material' in failure_cause(8, 'orange', details, materials, events,
                                                  where[8])[1]
    assert failure_cause(4, 'orange', details, materials, events)[1] == \
        'grasp: nothing within 4 mm'
    assert failure_cause(2, 'orange', details, materials, events)[1] == \
        'seen as purple, it is orange'


def test_the_report_counts_the_failures_by_cause(tmp_path):
    def trial(n, causes):
        return TrialResult('incomplete' if causes else 'completed', 60.0 + n, scenario_seed=n,
                           belt_speed=0.12, total=8,
                           not_at_destination=[{'id': k, 'color': 'orange', 'cause': c}
                                               for k, c in enumerate(causes)],
                           run=RunInfo(trial=n))
    trials = [trial(0, ['dropped', 'not_seen']), trial(1, ['not_seen']), trial(2, [])]
    text = write_report(trials, tmp_path, {'note': 'three'}).read_text()
    assert ('Materials not at their destination, by cause: not seen 2, dropped 1 (of 24 in 3 '
            'trials).') in text
    assert 'by cause' not in write_report(trials[2:], tmp_path, {'note': 'one'}).read_text()


def _belt_truth(t: float, speed: float = 0.12) -> list:
    """Ground truth at time ``t``: an orange riding the belt (at x -0.5 at t = 10 s) and a
    purple 0.3 m behind it."""
    x = -0.5 + speed * (t - 10.0)
    return [('orange', np.array([x, 0.75, 0.425])), ('purple', np.array([x - 0.3, 0.75, 0.425]))]


def test_an_identification_waits_for_the_truth_of_its_own_moment():
    ns = 1_000_000_000
    check = IdentificationCheck()
    # Only an older snapshot is in (under load the truth came late): the orange rode 6 cm on
    # since, more than the match's 4 cm. Decided on it, a correct identification was wrong.
    check.truth(int(9.5 * ns), _belt_truth(9.5))
    check.seen(10 * ns, [-0.5, 0.75, 0.425], 'orange', 7)
    assert check.results == []
    check.truth(10 * ns, _belt_truth(10.0))
    assert check.results == [True]
    # A wrong colour is wrong; one on nothing is wrong.
    check.seen(10 * ns, [-0.8, 0.75, 0.425], 'orange')
    check.truth(int(10.1 * ns), _belt_truth(10.1))
    check.unknown()
    assert check.results == [True, False, False]
    # What decided each one is kept, to read in the result.
    assert check.details[0] == {'stamp': 10.0, 'color': 'orange', 'material': 7,
                                'truth_id': 0, 'true_color': 'orange', 'distance': 0.0}
    assert check.details[1]['true_color'] == 'purple' and check.details[2]['color'] is None
    # Which of the simulator's materials each of the coordinator's is: the one seen on.
    assert tracks_of(check.details) == {0: 7}


def test_the_identifications_do_not_depend_on_when_the_truth_arrives():
    ns = 1_000_000_000
    stamps = [int(t * ns) for t in np.arange(9.0, 11.01, 0.1)]
    seen = [(int(9.73 * ns), [-0.5 + 0.12 * (9.73 - 10.0), 0.75, 0.425], 'orange'),
            (int(10.42 * ns), [-0.8 + 0.12 * 0.42, 0.75, 0.425], 'purple'),
            (int(10.42 * ns), [-0.5 + 0.12 * 0.42, 0.75, 0.425], 'purple')]
    outcomes = []
    for order in ('truth first', 'seen first', 'interleaved', 'shuffled'):
        check = IdentificationCheck()
        snaps = [(s, _belt_truth(s / ns)) for s in stamps]
        if order == 'shuffled':
            snaps = snaps[::2] + snaps[1::2]
        if order == 'truth first':
            for s in snaps:
                check.truth(*s)
            for d in seen:
                check.seen(*d)
        elif order == 'seen first':
            for d in seen:
                check.seen(*d)
            for s in snaps:
                check.truth(*s)
        else:
            pending = list(seen)
            for s in snaps:
                check.truth(*s)
                if pending and pending[0][0] <= s[0] + 0.3 * ns:
                    check.seen(*pending.pop(0))
            for d in pending:
                check.seen(*d)
        outcomes.append(check.finish())
    assert outcomes == [[True, True, False]] * 4


def test_identifications_left_at_the_end_are_decided_with_what_there_is():
    check = IdentificationCheck()
    check.seen(5, [0.0, 0.0, 0.0], 'orange')
    assert check.finish() == [False]                         # no truth at all
    check = IdentificationCheck()
    check.truth(1, [('orange', np.array([0.0, 0.0, 0.0]))])
    check.seen(5, [0.0, 0.0, 0.0], 'orange')
    assert check.finish() == [True]


def test_a_run_is_completed_only_if_the_ground_truth_has_every_material_at_its_destination(
        regions):
    """The coordinator believed all 8 delivered; the second purple lies on the first, one
    orange fell beside the pool: the result is incomplete and names both, and why."""
    truth = ([('purple', np.array([-0.5, 0.3, 0.027])), ('purple', np.array([-0.5, 0.3, 0.077]))]
             + [('orange', IN_POOL + [0.06 * k, 0, 0.0]) for k in range(4)]
             + [('orange', np.array([1.7, -1.3, 0.027])), ('blue', ON_PLATFORM)])
    out = score(_result(total=8), truth, [True] * 8, regions)
    assert out.status == 'incomplete' and out.handled_verified == 6
    missing = {m['id']: m for m in out.not_at_destination}
    assert sorted(missing) == [1, 6]
    assert missing[1]['why'].startswith('on ground_target but 0.075 m over its face, on another')
    assert missing[6]['why'] == 'not on pool_floor: at (1.700, -1.300, 0.027)'
    assert 'material 1 (purple) on ground_target' in out.message
    # Named by the coordinator's id too, where it saw the material (its log's, its result's).
    named = score(_result(total=8), truth, [True] * 8, regions, {1: 12, 0: 3})
    assert 'material 1 (purple, the coordinator\'s 12) on ground_target' in named.message
    assert 'material 6 (orange) not on pool_floor' in named.message
    assert [m['material'] for m in named.not_at_destination] == [12, -1]
    # All there: completed, nothing named.
    good = [truth[0]] + truth[2:6] + [('orange', IN_POOL + [0.0, 0.08, 0.0]), truth[7]]
    ok = score(_result(total=7), good, [True] * 7, regions)
    assert ok.status == 'completed' and ok.not_at_destination == []
    # A material that never appeared is not at its destination either.
    assert score(_result(total=8), good, [True] * 7, regions).status == 'incomplete'


def test_a_material_leaning_on_another_in_the_pool_is_not_delivered(regions):
    """An orange that ended leaning on another, its centre 49 mm over the pool's floor (a
    50 mm cube lying on it has its centre 25 mm up), was scored as delivered, and its run as
    completed. A cube that touches the floor however it lies has its centre at most half its
    space diagonal (43 mm) over it."""
    from trial_record.scoring import at_destination, why_not_there
    floor = 0.002                                            # the pool floor's top face
    for height, there in ((0.025, True), (0.0354, True), (0.043, True), (0.049, False),
                          (0.075, False)):
        assert at_destination('orange', (2.1, -1.3, floor + height), regions) is there, height
    assert 'on another material' in why_not_there('orange', (2.1, -1.3, floor + 0.049), regions)
