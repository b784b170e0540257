"""The study tools against records from elsewhere (issue 47): a sweep with a typo, a bag copied
and edited, a damaged result or bag, an output path that cannot be written. Each is refused in
one line with exit code 2 before any work starts, and leaves nothing half-written; and exit
codes tell the truth."""
import json
import math
import os
import resource
import sys
import time

import pytest
from rclpy.serialization import serialize_message
from sim_interfaces.msg import PipelineState

from recording.bag_writer import BagWriter
from studies import compare, run_trials, trial_process
from studies.recorded import STATE_TOPIC, TRIAL_KEY, bag_metadata
from studies.sweep import SweepError, grid, parse_axis
from trial_record.records import RecordError, parse_json
from trial_record.result import RunInfo, TrialResult, read_result
from world_description.resources import resolve_resource
from world_description.world_config import world_data

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')
SCENARIO = {'world': str(CELL), 'world_data': world_data(CELL), 'time_step': 1 / 240}


def _result(**changes):
    fields = dict(status='completed', completion_time=60.1, scenario_seed=7, belt_speed=0.12,
                  total=8, delivered=8, handled_verified=8, identified_correct=8,
                  events=[[0.0, 'belt_started', '', -1, '', ''],
                          [60.1, 'finished', '', -1, '', '']],
                  states=[[0.0, 'loader', 'pick'], [60.1, 'loader', 'done']],
                  youbot_path=[[0.8, 0.05], [1.5, -1.0]], scenario=dict(SCENARIO),
                  run=RunInfo(trial=0, code='abc', wall_time=40.0))
    fields.update(changes)
    return TrialResult(**fields)


def _bag(directory, trial_json, result=None):
    writer = BagWriter(directory, 'bag', 'mcap', custom_data={TRIAL_KEY: trial_json})
    writer.add_topic(STATE_TOPIC, 'sim_interfaces/msg/PipelineState')
    writer.write(STATE_TOPIC, 1, serialize_message(PipelineState(
        status='completed', result_json=(result or _result()).to_json())))
    writer.close()
    return writer.path


def _trial_json(**changes):
    data = json.loads(bag_metadata(0, 7, 0.12, 'abc', SCENARIO)[TRIAL_KEY])
    data.update(changes)
    return json.dumps(data)


def _one_line_and_2(capsys, code, *fragments):
    err = capsys.readouterr().err
    assert code == 2, err
    assert 'Traceback' not in err and len(err.strip().splitlines()) == 1, err
    for fragment in fragments:
        assert fragment in err, err
    return err


# --- sweeps -------------------------------------------------------------------------------------
@pytest.mark.parametrize('spec', ['belt_speed=0:1e12:1', 'belt_speed=0:1e308:1e-308',
                                  'belt_speed=' + ','.join(['0.1'] * 500)])
def test_a_sweep_of_too_many_points_is_refused_before_any_is_made(spec):
    """0:1e12:1 took 2.6 GB in 30 s before its count was checked (a MemoryError traceback);
    0:1e308:1e-308, an OverflowError traceback. Here under a memory limit of 1 GB."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with pytest.raises(SweepError, match='400'):
        try:
            resource.setrlimit(resource.RLIMIT_AS, (max(1 << 30, _used() + (256 << 20)), hard))
            parse_axis(spec)
        finally:
            resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _used():
    with open('/proc/self/statm') as f:
        return int(f.read().split()[0]) * os.sysconf('SC_PAGE_SIZE')


def test_a_grid_is_counted_before_it_is_made():
    axes = [parse_axis('belt_speed=0.1:0.5:0.002'), parse_axis('materials.mass=0.1:0.5:0.002')]
    with pytest.raises(SweepError, match='40401 points'):
        grid(axes)


def test_a_sweep_over_a_world_value_out_of_its_range_leaves_nothing(tmp_path, capsys):
    out = tmp_path / 'sweep'
    code = run_trials.main(['--sweep', 'gravity=1e300,2e300', '--out', str(out)])
    _one_line_and_2(capsys, code, 'gravity', '1e+300')
    assert not out.exists()


# --- a bag's trial record -----------------------------------------------------------------------
DEEP = '[' * 100_000 + ']' * 100_000
BAD_RECORDS = {
    'scenario a string': _trial_json(scenario='cell.yaml'),
    'parameters a list': _trial_json(parameters=[1, 2]),
    'a 100,000-deep JSON': DEEP,
    'time_step a string': _trial_json(scenario={**SCENARIO, 'time_step': 'x'}),
    'trial a path': _trial_json(trial='../../evil'),
    'gravity 1e300': _trial_json(scenario={**SCENARIO, 'world_data': {
        **SCENARIO['world_data'], 'gravity': 1e300}}),
    'belt speed 1e9': _trial_json(belt_speed=1e9),
}


@pytest.mark.parametrize('name', list(BAD_RECORDS))
def test_a_bags_trial_record_is_checked_before_anything_uses_it(tmp_path, capsys, monkeypatch,
                                                                 name):
    """Each gave a traceback in run_trials --rerun, compare_runs or storyboard (or started a
    trial and then crashed): now one line and exit 2, and no trial starts."""
    from studies import storyboard
    monkeypatch.setattr(trial_process, 'run_trial', _no_trial)
    bag = _bag(tmp_path / 'copied', BAD_RECORDS[name])
    out = tmp_path / 'again'
    _one_line_and_2(capsys, run_trials.main(['--rerun', str(bag), '--out', str(out)]))
    _one_line_and_2(capsys, compare.main([str(bag), str(bag), '--out', str(tmp_path / 'c')]))
    _one_line_and_2(capsys, storyboard.main([str(bag), '-o', str(tmp_path / 's.png')]))
    assert not (tmp_path / 'c').exists() and not (tmp_path / 's.png').exists()
    assert not (out / 'trial_000').exists()


def test_a_world_whose_robot_files_are_not_there_is_refused_before_it_runs(tmp_path, capsys,
                                                                            monkeypatch):
    """A robot URDF path in the embedded world was not checked before the trial started: the
    re-run and the storyboard (which build the cell) refuse it first."""
    from studies import storyboard
    monkeypatch.setattr(trial_process, 'run_trial', _no_trial)
    robots = [{**r, 'urdf': '/nowhere/robot.urdf'} for r in SCENARIO['world_data']['robots']]
    bag = _bag(tmp_path / 'copied', _trial_json(scenario={
        **SCENARIO, 'world_data': {**SCENARIO['world_data'], 'robots': robots}}))
    _one_line_and_2(capsys, run_trials.main(['--rerun', str(bag), '--out', str(tmp_path / 'a')]),
                    '/nowhere/robot.urdf')
    _one_line_and_2(capsys, storyboard.main([str(bag), '-o', str(tmp_path / 's.png')]),
                    '/nowhere/robot.urdf')


def _no_trial(*args, **kwargs):
    raise AssertionError('a trial was started')


def test_a_good_bag_record_still_reads(tmp_path):
    from studies.recorded import load_trial
    result, source = load_trial(_bag(tmp_path, _trial_json()))
    assert (result.trial, result.scenario_seed, result.status) == (0, 7, 'completed')


def test_a_bag_with_a_zeroed_block_is_one_line(tmp_path, capsys):
    """An MCAP whose middle was zeroed: rosbags raised OverflowError (a traceback)."""
    from studies import storyboard
    writer = BagWriter(tmp_path, 'bag', 'mcap', custom_data={TRIAL_KEY: _trial_json()})
    writer.add_topic(STATE_TOPIC, 'sim_interfaces/msg/PipelineState')
    for i in range(400):
        writer.write(STATE_TOPIC, i, serialize_message(PipelineState(
            status='running', result_json='')))
        if i % 50 == 49:
            writer.flush()                       # (a chunk)
    writer.write(STATE_TOPIC, 400, serialize_message(PipelineState(
        status='completed', result_json=_result().to_json())))
    writer.close()
    mcap = next(writer.path.glob('*.mcap'))
    size = mcap.stat().st_size
    with open(mcap, 'r+b') as f:
        f.seek(size // 3)
        f.write(b'\0' * 4096)
    _one_line_and_2(capsys, storyboard.main([str(writer.path), '-o', str(tmp_path / 's.png')]),
                    'bag_repair')
    _one_line_and_2(capsys, compare.main([str(writer.path), str(writer.path), '--out',
                                          str(tmp_path / 'c')]), 'bag_repair')


# --- result files -------------------------------------------------------------------------------
BAD_RESULTS = {
    'completion time 1e12': {'completion_time': 1e12},
    'an event that is no event': {'events': [[0.0, 'picked']]},
    'a path point of three': {'youbot_path': [[0.0, 1.0, 2.0]]},
    'a material without a colour': {'materials': [{'id': 1, 'status': 'missed',
                                                   'failure': 'dropped'}]},
    'a status of its own': {'status': 'splendid'},
    'a deep identification': {'identifications': [{'stamp': [[[[1]]]]}]},
    'an unknown field': {'surprise': 1},
}


@pytest.mark.parametrize('name', list(BAD_RESULTS))
def test_a_damaged_result_is_refused_by_every_tool(tmp_path, capsys, name):
    """completion_time 1e12 made compare_runs and run_trials --report-only loop for hours (and
    the report left PNGs without report.md)."""
    good = _result()
    for k in range(2):
        good.with_run(trial=k).write(tmp_path / 'campaign' / f'trial_{k:03d}' / 'result.json')
    path = tmp_path / 'campaign' / 'trial_001' / 'result.json'
    data = json.loads(path.read_text())
    data.update(BAD_RESULTS[name])
    path.write_text(json.dumps(data))
    started = time.monotonic()
    _one_line_and_2(capsys, run_trials.main(['--report-only', '--out',
                                             str(tmp_path / 'campaign')]), 'trial_001')
    _one_line_and_2(capsys, compare.main([str(path), str(path), '--out', str(tmp_path / 'c')]))
    _one_line_and_2(capsys, compare.main([str(tmp_path / 'campaign'), str(tmp_path / 'campaign'),
                                          '--out', str(tmp_path / 'c')]))
    assert time.monotonic() - started < 60.0
    # (Nothing but the runner's lock, which holds the directory while it reads it.)
    assert sorted(p.name for p in (tmp_path / 'campaign').iterdir()) == [
        '.run_trials.lock', 'trial_000', 'trial_001']
    assert not (tmp_path / 'c').exists()


def test_what_a_result_writes_reads_back():
    """The writer never writes what the reader refuses: a message is cut to its limit."""
    r = _result(message='x' * 1_000_000)
    again, problem = TrialResult.from_dict(json.loads(r.to_json())), None
    assert problem is None and again.differences(r) == [] and len(again.message) == 100_000


def test_a_record_file_that_is_no_file_is_refused(tmp_path):
    fifo = tmp_path / 'result.json'
    os.mkfifo(fifo)
    result, problem = read_result(fifo)          # (a FIFO blocked the reader)
    assert result is None and 'not a regular file' in problem
    with pytest.raises(RecordError, match='nested too deeply'):
        parse_json(DEEP, 'x')


# --- output paths and exit codes ----------------------------------------------------------------
def test_output_paths_are_checked_before_the_work(tmp_path, capsys):
    from studies import storyboard
    run = tmp_path / 'run'
    _result().write(run / 'trial_000' / 'result.json')
    (tmp_path / 'file').write_text('x')
    _one_line_and_2(capsys, compare.main([str(run), str(run), '--out',
                                          str(tmp_path / 'file' / 'out')]), 'not a directory')
    _one_line_and_2(capsys, compare.main([str(run), str(run), '--out', str(tmp_path / 'file')]),
                    'not a directory')
    _one_line_and_2(capsys, storyboard.main([str(run), '-o', str(tmp_path)]), 'a directory')
    _one_line_and_2(capsys, storyboard.main([str(run), '-o', str(tmp_path / 'picture')]),
                    '.png')
    _one_line_and_2(capsys, run_trials.main(['--rerun', str(run), '--out',
                                         str(tmp_path / 'file' / 'x')]), 'not a directory')
    assert compare.main([str(run), str(run), '--out', str(tmp_path / 'ok')]) == 0
    assert (tmp_path / 'ok' / 'comparison.md').is_file()
    assert not [p for p in tmp_path.iterdir() if '.partial' in p.name]


def test_a_failed_report_leaves_the_campaign_directory_as_it_was(tmp_path, monkeypatch):
    from studies import report
    campaign = tmp_path / 'campaign'
    _result().write(campaign / 'trial_000' / 'result.json')

    def broken(*args, **kwargs):
        raise OSError('disk full')
    monkeypatch.setattr(report, 'timeline', broken)
    with pytest.raises(OSError):
        report.write_report([_result()], campaign, {'note': 'x'})
    assert sorted(p.name for p in campaign.iterdir()) == ['trial_000']
    assert not [p for p in tmp_path.iterdir() if '.partial' in p.name]


@pytest.mark.slow
@pytest.mark.parametrize('status, code', [('error', 1), ('node_timeout', 1), ('completed', 0),
                                          ('incomplete', 0)])
def test_a_rerun_that_did_not_run_exits_1(tmp_path, monkeypatch, capsys, status, code):
    """run_trials --rerun RUN --set ... exited 0 when the re-run ended in error."""
    run = tmp_path / 'run'
    _result().write(run / 'trial_000' / 'result.json')

    def fake_trial(trial, seed, belt_speed, domain_id, out_dir, wall_timeout, record, code,
                   world, time_step, parameters=None):
        return _result(status=status, completion_time=math.nan,
                       message='sim_node exited 1' if status == 'error' else '',
                       run=RunInfo(trial=trial, wall_time=1.0, code=code))
    monkeypatch.setattr(trial_process, 'run_trial', fake_trial)
    assert run_trials.main(['--rerun', str(run), '--set', 'belt_speed=0.2', '--out',
                        str(tmp_path / 'again')]) == code
    if code:
        assert 'did not run to its end' in capsys.readouterr().out


if __name__ == '__main__':          # (a quick manual run)
    sys.exit(pytest.main([__file__, '-q']))
