"""Re-running a recorded trial (studies/rerun.py): what a result must hold, --set, where
two runs part."""
import json

import pytest
import yaml

from studies.recorded import RecordError, find_result
from studies.rerun import (
    ORIGINAL_WORLD,
    RerunError,
    figures,
    first_parting,
    parse_sets,
    prepare,
)
from trial_record.result import RunInfo, TrialResult
from world_description.resources import resolve_resource
from world_description.world_config import load_world, world_data

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')


def _recorded(tmp_path, **scenario):
    trial = tmp_path / 'demo' / 'trial_000'
    trial.mkdir(parents=True)
    result = TrialResult('completed', 60.1, scenario_seed=0, belt_speed=0.12, total=8,
                         events=[[0.0, 'belt_started', '', -1, '', ''],
                                 [1.1, 'seen', 'vision', 1, 'orange', 'at x']],
                         scenario={'world': str(CELL), 'world_data': world_data(CELL),
                                   'time_step': 1 / 240, **scenario},
                         run=RunInfo(trial=0, code='abc'))
    result.write(trial / 'result.json')
    return result


def test_a_run_is_found_by_its_result_its_trial_or_its_run_directory(tmp_path):
    _recorded(tmp_path)
    path = tmp_path / 'demo' / 'trial_000' / 'result.json'
    assert find_result(path) == path
    assert find_result(path.parent) == path
    assert find_result(tmp_path / 'demo') == path
    (tmp_path / 'demo' / 'trial_001').mkdir()
    (tmp_path / 'demo' / 'trial_001' / 'result.json').write_text('{}')
    with pytest.raises(RecordError, match='holds 2 trials'):
        find_result(tmp_path / 'demo')
    with pytest.raises(RecordError, match='no trial result'):
        find_result(tmp_path)


def test_the_rerun_takes_the_world_as_it_was_and_the_changes(tmp_path):
    _recorded(tmp_path)
    rerun = prepare(tmp_path / 'demo', ['belt_speed=0.2', 'perturbations.camera.blur=1.5'],
                    tmp_path / 'again')
    assert (rerun.seed, rerun.belt_speed, rerun.time_step) == (0, 0.2, 1 / 240)
    assert rerun.changes == {'belt_speed': 0.2, 'perturbations.camera.blur': 1.5}
    assert rerun.world == str(tmp_path / 'again' / ORIGINAL_WORLD)
    # The world as it was: the same world as the cell's, though written elsewhere.
    assert load_world(rerun.world).materials == load_world(CELL).materials
    assert yaml.safe_load(open(rerun.world))['conveyor'] == world_data(CELL)['conveyor']
    unchanged = prepare(tmp_path / 'demo', [], tmp_path / 'same')
    assert (unchanged.belt_speed, unchanged.changes) == (0.12, {})


def test_what_cannot_be_run_again_is_said(tmp_path):
    _recorded(tmp_path)
    for sets, says in [(['belt_speed'], 'give NAME=NUMBER'), (['x=nan'], 'give NAME=NUMBER'),
                       (['perturbations.camera.blurr=1'], "unknown keys ['blurr']"),
                       (['belt_speed=-1'], 'cannot be run')]:
        with pytest.raises(RerunError) as err:
            prepare(tmp_path / 'demo', sets, tmp_path / 'x')
        assert says in str(err.value), (sets, str(err.value))
    old = tmp_path / 'old' / 'trial_000'
    old.mkdir(parents=True)
    (old / 'result.json').write_text(json.dumps({'status': 'completed', 'scenario_seed': 4}))
    with pytest.raises(RerunError, match='does not keep the world'):
        prepare(old, [], tmp_path / 'y')


def test_a_worlds_own_relative_files_are_found_from_anywhere(tmp_path):
    (tmp_path / 'cell').mkdir()
    urdf = resolve_resource('package://robot_description/urdf/zu12.urdf')
    (tmp_path / 'cell' / 'arm.urdf').write_text(urdf.read_text())
    text = CELL.read_text().replace('package://robot_description/urdf/zu12.urdf', 'arm.urdf')
    text = text.replace('package://robot_description/config/zu12_joint_limits.yaml',
                        str(resolve_resource('package://robot_description/config/'
                                             'zu12_joint_limits.yaml')))
    (tmp_path / 'cell' / 'world.yaml').write_text(text)
    data = world_data(tmp_path / 'cell' / 'world.yaml')
    assert data['robots'][0]['urdf'] == str(tmp_path / 'cell' / 'arm.urdf')
    assert data['robots'][1]['urdf'] == 'package://robot_description/urdf/youbot.urdf'
    moved = tmp_path / 'elsewhere.yaml'
    moved.write_text(yaml.safe_dump(data))
    assert load_world(moved).robots[0].urdf == str(tmp_path / 'cell' / 'arm.urdf')
    # A world elsewhere that extends it (a sweep's point in a trial's directory): the base's own
    # files stay where the base is (they were looked for beside the world that extends it).
    (tmp_path / 'trial').mkdir()
    point = tmp_path / 'trial' / 'world.yaml'
    point.write_text(f'extends: {tmp_path / "cell" / "world.yaml"}\nmaterials: {{mass: 0.2}}\n')
    assert world_data(point)['robots'][0]['urdf'] == str(tmp_path / 'cell' / 'arm.urdf')


def test_changes_are_numbers_by_name():
    assert parse_sets(['belt_speed=0.2', ' materials.mass = 0.3']) == {
        'belt_speed': 0.2, 'materials.mass': 0.3}
    for bad in ('=1', 'x=', 'x=inf', 'x'):
        with pytest.raises(RerunError):
            parse_sets([bad])


def test_where_two_runs_part():
    a = TrialResult('completed', 60.0, events=[[0.0, 'belt_started', '', -1, '', ''],
                                               [2.8, 'picked', 'zu12', 1, 'orange', 'attempt 1']])
    b = TrialResult('incomplete', 61.0, events=[[0.0, 'belt_started', '', -1, '', ''],
                                                [2.9, 'picked', 'zu12', 1, 'orange', 'attempt 1'],
                                                [3.0, 'seen', 'vision', 2, 'blue', '']])
    assert first_parting(a, a) == ''
    assert first_parting(a, b) == ('event 1: [2.8 s] zu12 picked orange material 1 (attempt 1) '
                                   'in the first run, [2.9 s] zu12 picked orange material 1 '
                                   '(attempt 1) in the second run')
    assert first_parting(a, TrialResult('completed', events=a.events + b.events[2:])) == \
        'event 2: the second run goes on with [3.0 s] vision seen blue material 2'
    assert ('status', 'completed', 'incomplete') in figures(a, b)
    assert ('completion time [s]', '60.000', '61.000') in figures(a, b)
