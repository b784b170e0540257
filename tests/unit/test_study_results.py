"""A study never loses, reuses wrongly or invents a result (issue 62): each failure found by the
fourth round of probes, run through ``run_trials`` as a user runs it, on a made-up cell (a
trial written as the runner writes one, with the world it ran) or on the real trial runner
whose processes cannot start."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Callable, Dict, List, Optional

import pytest
import yaml

import studies.run_trials as trials
import studies.trial_process as trial_run
from helpers import ROOT
from studies.sweep import point_world
from studies.trial_process import scenario
from trial_record.result import RunInfo, TrialResult

CELL = 'package://world_description/worlds/pipeline_cell.yaml'
SHIPPED = 'package://studies/study_files/'


def _search(world: str = CELL, **search: object) -> Dict[str, object]:
    return {'question': 'the fastest belt', 'world': world, 'seed': 5,
            'factors': {'belt_speed': {'low': 0.05, 'high': 0.35, 'step': 0.1}},
            'search': {'maximise': 'belt_speed',
                       'subject_to': {'response': 'handling', 'at_least': 0.5},
                       'trials_per_setting': 2, 'budget': 8, **search}}


def _file(tmp_path: Path, data: Dict[str, object], name: str = 'study.yaml') -> Path:
    path = tmp_path / 'in' / name
    path.parent.mkdir(exist_ok=True)
    path.write_text(yaml.safe_dump(data))
    return path


class Cell:
    """A made-up cell in place of a trial's processes: each trial writes its result as the
    runner does (the world it ran, its physics step, the code), handling every material below
    0.2 m/s and half of them above. ``stop_at``: the trial at which the user presses Ctrl-C."""

    def __init__(self, stop_at: Optional[int] = None) -> None:
        self.ran: List[int] = []
        self.stop_at = stop_at

    def __call__(self, trial: int, seed: int, belt_speed: float, domain_id: int, out_dir: Path,
                 wall_timeout: float = 900.0, record: bool = False, code: str = '',
                 world: str = CELL, time_step: float = 1 / 240,
                 parameters: Optional[Dict[str, float]] = None) -> TrialResult:
        if trial == self.stop_at:
            raise KeyboardInterrupt
        self.ran.append(trial)
        trial_dir = out_dir / f'trial_{trial:03d}'
        trial_dir.mkdir(exist_ok=True)
        ran = scenario(point_world(world, dict(parameters or {}), trial_dir), time_step)
        total = sum(ran['world_data']['materials']['counts'].values())
        handled = total if belt_speed < 0.2 else total // 2
        result = TrialResult('completed' if handled == total else 'incomplete', 60.0,
                             scenario_seed=seed, belt_speed=belt_speed, total=total,
                             handled_verified=handled, identified_correct=total,
                             grasp_attempts=total, grasp_successes=total,
                             parameters=dict(parameters or {}), scenario=ran,
                             run=RunInfo(trial=trial, code=code, wall_time=1.0))
        result.write(trial_dir / 'result.json')
        return result


@pytest.fixture
def cell(monkeypatch: pytest.MonkeyPatch) -> Callable[..., Cell]:
    monkeypatch.setattr(trials, 'code_version', lambda: 'abc123')

    def install(stop_at: Optional[int] = None) -> Cell:
        fake = Cell(stop_at)
        monkeypatch.setattr(trial_run, 'run_trial', fake)
        return fake
    return install


def _run(argv: List[str]) -> int:
    return trials.main([*argv, '--progress-period', '0.01'])


def _one_line(capsys: pytest.CaptureFixture[str], code: int, *words: str) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith('run_trials: error:'), err
    assert all(w in lines[0] for w in words), err
    return lines[0]


# -- a directory holds one kind of run --------------------------------------------------------

def test_a_campaigns_resume_refuses_a_study_and_changes_nothing(tmp_path, cell, capsys):
    """`run_trials --resume STUDYDIR` ran the default campaign into the study's directory and
    replaced its trial_000."""
    cell()
    study, out = _file(tmp_path, _search()), tmp_path / 'study'
    assert _run(['--study', str(study), '--out', str(out)]) == 0
    before = {p: p.read_bytes() for p in out.rglob('*') if p.is_file()}
    capsys.readouterr()
    _one_line(capsys, _run(['--resume', str(out)]), 'holds a study (study.json), not a '
              'campaign', f'--study {out / "study.yaml"} --resume {out}')
    _one_line(capsys, _run(['--out', str(out)]), 'holds a study')
    _one_line(capsys, _run(['--report-only', '--out', str(out)]), 'holds a study')
    after = {p: p.read_bytes() for p in out.rglob('*') if p.is_file()
             and p.name != '.run_trials.lock'}
    assert after == {p: b for p, b in before.items() if p.name != '.run_trials.lock'}
    # And the other way: a campaign's directory is no study's.
    campaign = tmp_path / 'campaign'
    assert _run(['--trials', '1', '--out', str(campaign)]) == 0
    _one_line(capsys, _run(['--study', str(study), '--resume', str(campaign)]),
              'holds a campaign (campaign.json), not a study', f'--resume {campaign}')
    _one_line(capsys, _run(['--study', str(study), '--out', str(campaign)]), 'holds a campaign')
    empty = tmp_path / 'empty'
    empty.mkdir()
    _one_line(capsys, _run(['--resume', str(empty)]), 'holds no campaign')


@pytest.mark.slow
def test_make_study_resume_goes_on_with_what_the_directory_holds(tmp_path, monkeypatch):
    """`make study RESUME=DIR` without STUDY= started a new sweep. Here DIR holds a finished
    study whose every trial ran as it would now (this checkout's code): it is taken whole, no
    trial runs, and the answer is written again; a directory of nothing is refused."""
    monkeypatch.setattr(trial_run, 'run_trial', Cell())
    study, out = _file(tmp_path, _search()), tmp_path / 'study'
    assert _run(['--study', str(study), '--out', str(out)]) == 0
    answer = json.loads((out / 'study.json').read_text())['answer']
    (out / 'study.md').unlink()
    env = {**os.environ, 'RESUME': str(out), 'PARALLEL': '1'}
    done = subprocess.run(['bash', str(ROOT / 'scripts' / 'study.sh')], env=env, text=True,
                          capture_output=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f'0 run now, {answer["trials"]} taken from this directory' in \
        (out / 'study.md').read_text()
    assert json.loads((out / 'study.json').read_text())['answer'] == answer
    nothing = tmp_path / 'nothing'
    nothing.mkdir()
    done = subprocess.run(['bash', str(ROOT / 'scripts' / 'study.sh')], text=True,
                          env={**env, 'RESUME': str(nothing)}, capture_output=True, timeout=60)
    assert done.returncode == 2 and 'holds no campaign' in done.stderr, done.stderr


# -- only trials that ran are evidence ----------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize('shipped', ['belt_speed.yaml', 'perturbation_screening.yaml'])
def test_a_study_whose_trials_cannot_run_has_no_answer(tmp_path, monkeypatch, capsys, shipped):
    """With the simulator's executables missing, the shipped search said "no setting of the 6
    tried meets the constraint (36 trials)" and exited 0; the screening exited 0 with
    `ranking: null`. Once the cause is fixed, none of those failed trials is reused."""
    monkeypatch.setenv('PATH', str(tmp_path / 'nothing_here'))
    out = tmp_path / 'study'
    code = _run(['--study', SHIPPED + shipped, '--out', str(out), '--wall-timeout', '30'])
    printed = capsys.readouterr().out
    assert code == 1, printed
    assert 'did not run: error: cannot start sim_node' in printed
    assert 'no answer' in printed and 'says nothing about the cell' in printed
    assert 'meets the constraint' not in printed and 'ranking' not in printed
    assert 'answer' not in json.loads((out / 'study.json').read_text())
    assert not (out / 'study.md').exists()
    failed = sorted(p.parent.name for p in out.glob('trial_*/result.json'))
    assert failed and all(json.loads((out / t / 'result.json').read_text())['status']
                          == 'error' for t in failed)
    # The cause fixed: every trial runs, none of the failed ones is taken.
    fake = Cell()
    monkeypatch.setattr(trial_run, 'run_trial', fake)
    # (PATH stays empty: nothing else may start; the code is 'unknown' without git.)
    assert _run(['--study', str(out / 'study.yaml'), '--resume', str(out)]) == 0
    printed = capsys.readouterr().out
    assert {f'trial_{t:03d}' for t in fake.ran} >= set(failed)
    assert f'runs again: its result ({failed[0]}) did not run (error)' in printed
    assert '0 taken from this directory' in (out / 'study.md').read_text()


# -- a trial is reused only for what it ran -----------------------------------------------------

def test_a_trial_of_another_world_or_step_is_not_reused(tmp_path, cell, capsys):
    """A study whose local world file changed between runs reused a trial of the 8-material
    world for a 3-material one."""
    world = tmp_path / 'in' / 'cell.yaml'
    world.parent.mkdir()
    world.write_text(f'extends: {CELL}\n')
    study, out = _file(tmp_path, _search(world=str(world))), tmp_path / 'study'
    fake = cell()
    assert _run(['--study', str(study), '--out', str(out)]) == 0
    first = list(fake.ran)
    assert first and all(json.loads((out / f'trial_{t:03d}' / 'result.json').read_text())
                         ['total'] == 8 for t in first)
    world.write_text(f'extends: {CELL}\nmaterials:\n  counts: {{purple: 1, orange: 1, '
                     'blue: 1}\n')
    fake.ran.clear()
    assert _run(['--study', str(study), '--resume', str(out)]) == 0
    printed = capsys.readouterr().out
    assert sorted(fake.ran) == sorted(first)                  # every trial again
    assert 'is of another world (the world file has changed since)' in printed
    assert all(json.loads((out / f'trial_{t:03d}' / 'result.json').read_text())['total'] == 3
               for t in first)
    # Resumed as it is, every trial is taken; at another physics step, refused.
    fake.ran.clear()
    assert _run(['--study', str(study), '--resume', str(out)]) == 0 and fake.ran == []
    _one_line(capsys, _run(['--study', str(study), '--resume', str(out), '--time-step',
                            '0.002']), '--time-step 0.002 differs from the study being resumed')


def test_a_campaign_reuses_no_trial_of_another_world(tmp_path, cell, capsys):
    world = tmp_path / 'cell.yaml'
    world.write_text(f'extends: {CELL}\n')
    out = tmp_path / 'campaign'
    fake = cell(stop_at=1)
    assert _run(['--trials', '2', '--world', str(world), '--out', str(out)]) == 130
    world.write_text(f'extends: {CELL}\nmaterials:\n  mass: 0.2\n')
    fake.stop_at, fake.ran = None, []
    assert _run(['--resume', str(out)]) == 0
    assert fake.ran == [0, 1]
    assert 'trial 0 runs again: its result (trial_000) is of another world' in \
        capsys.readouterr().out


def test_a_stop_keeps_the_trials_the_study_reused(tmp_path, cell, capsys):
    """Stopping a resumed study that reused trial 0 wrote a trials.csv with no rows and said
    "stopped: 0 trials kept"."""
    study, out = _file(tmp_path, _search()), tmp_path / 'study'
    cell(stop_at=1)
    assert _run(['--study', str(study), '--out', str(out)]) == 130
    assert 'stopped: 1 trials kept' in capsys.readouterr().out
    fake = cell(stop_at=1)                       # (trial 0 is taken, trial 1 stopped again)
    assert _run(['--study', str(study), '--resume', str(out)]) == 130
    assert fake.ran == [] and 'stopped: 1 trials kept' in capsys.readouterr().out
    rows = (out / 'trials.csv').read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith('0,')


# -- nothing is written outside the output directory --------------------------------------------

PLANTED = ('study.yaml', 'study.json.new', 'trials.csv', 'trials.csv.new',
           'study.md', 'study_search.png', 'campaign.json.new', 'report.md')


def test_links_planted_in_a_study_are_replaced_not_written_through(tmp_path, cell):
    study, out, outside = _file(tmp_path, _search()), tmp_path / 'study', tmp_path / 'outside'
    out.mkdir()
    outside.mkdir()
    for name in PLANTED:
        (outside / name).write_text('keep me')
        (out / name).symlink_to(outside / name)
    cell()
    assert _run(['--study', str(study), '--out', str(out)]) == 0
    assert all((outside / name).read_text() == 'keep me' for name in PLANTED)
    assert (out / 'study.md').is_file() and not (out / 'study.md').is_symlink()
    assert not (out / 'study.json').is_symlink() and not (out / 'trials.csv').is_symlink()


def test_links_planted_in_a_campaign_are_replaced_not_written_through(tmp_path, cell):
    out, outside = tmp_path / 'campaign', tmp_path / 'outside'
    out.mkdir()
    outside.mkdir()
    for name in ('campaign.json', 'campaign.json.new', 'trials.csv', 'trials.csv.new',
                 'report.md'):
        (outside / name).write_text('keep me')
        (out / name).symlink_to(outside / name)
    (out / 'campaign.json').unlink()             # (a campaign's mark: a new one, then)
    cell()
    assert _run(['--trials', '2', '--out', str(out)]) == 0
    assert all(p.read_text() == 'keep me' for p in outside.iterdir())
    assert (out / 'campaign.json').is_file() and not (out / 'trials.csv').is_symlink()


def test_a_planted_lock_is_refused_in_one_line(tmp_path, cell, capsys):
    out, victim = tmp_path / 'study', tmp_path / 'victim'
    out.mkdir()
    victim.write_text('keep me')
    (out / '.run_trials.lock').symlink_to(victim)
    cell()
    _one_line(capsys, _run(['--study', str(_file(tmp_path, _search())), '--out', str(out)]),
              'the campaign lock', 'is a symbolic link')
    os.link(victim, tmp_path / 'hard')
    (out / '.run_trials.lock').unlink()
    os.link(victim, out / '.run_trials.lock')
    _one_line(capsys, _run(['--trials', '1', '--out', str(out)]), 'not a plain file of its own')
    assert victim.read_text() == 'keep me'


def test_a_trial_directory_that_is_a_link_is_not_written_through(tmp_path, monkeypatch):
    """The trial runner's own files (its directory, its logs, its result): a link planted for
    any of them leaves what it points at as it was."""
    from studies.trial_process import run_trial
    monkeypatch.setenv('PATH', str(tmp_path / 'nothing_here'))
    outside = tmp_path / 'outside'
    outside.mkdir()
    (outside / 'sim_node.log').write_text('keep me')
    out = tmp_path / 'campaign'
    out.mkdir()
    (out / 'trial_003').symlink_to(outside)
    result = run_trial(3, 11, 0.12, 231, out, wall_timeout=5.0)
    assert result.status == 'error' and 'is a symbolic link' in result.message
    assert [p.name for p in outside.iterdir()] == ['sim_node.log']
    (out / 'trial_003').unlink()
    (out / 'trial_003').mkdir()
    for name in ('sim_node.log', 'result.json', 'result.json.new'):
        (outside / name).write_text('keep me')
        (out / 'trial_003' / name).symlink_to(outside / name)
    result = run_trial(3, 11, 0.12, 231, out, wall_timeout=5.0)
    assert result.status == 'error' and 'cannot start sim_node' in result.message
    assert all(p.read_text() == 'keep me' for p in outside.iterdir())
    assert 'cannot start sim_node' in (out / 'trial_003' / 'sim_node.log').read_text()


# -- inputs the checks accepted, and tracebacks -------------------------------------------------

@pytest.mark.parametrize('change, words', [
    ({'factors': {'belt_speed': {'low': 0.05, 'high': 0.35, 'step': 1e-300}}},
     ('factors.belt_speed', 'at most 100000')),
    ({'factors': {'conveyor': {'low': 1, 'high': 2},
                  'conveyor.length': {'low': 1, 'high': 2}},
      'search': {'minimise': 'completion_time', 'trials_per_setting': 2, 'budget': 4}},
     ('factors name conveyor and conveyor.length, which is a part of it',)),
    ({'factors': {'materials.counts.orange': {'low': 4, 'high': 8}},
      'search': {'minimise': 'completion_time', 'trials_per_setting': 2, 'budget': 4}},
     ('factors.materials.counts.orange takes', 'must be an integer', 'step: 1')),
    ({'search': {**_search()['search'], 'trials_per_setting': True}},  # type: ignore[dict-item]
     ('search.trials_per_setting must be an integer',)),
    ({'factors': {'belt_speed': {'low': -1e308, 'high': 1e308}}},
     ('factors.belt_speed: high - low must be a finite number',)),
])
def test_a_study_the_checks_took_is_one_line_before_any_trial(tmp_path, cell, capsys, change,
                                                              words):
    fake = cell()
    out = tmp_path / 'study'
    _one_line(capsys, _run(['--study', str(_file(tmp_path, {**_search(), **change})),
                            '--out', str(out)]), *words)
    assert fake.ran == [] and not list(out.glob('trial_*'))


def test_a_factor_given_twice_is_one_line(tmp_path, cell, capsys):
    path = _file(tmp_path, _search())
    path.write_text(path.read_text().replace(
        'factors:\n', 'factors:\n  belt_speed: {low: 0.1, high: 0.2}\n'))
    _one_line(capsys, _run(['--study', str(path), '--out', str(tmp_path / 'o')]),
              'at line 3', "the key 'belt_speed' is given twice")


@pytest.mark.parametrize('step, words', [('nan', 'time_step must be within'),
                                         ('0', 'time_step must be within'),
                                         ('1', 'time_step must be within')])
def test_a_studys_physics_step_is_checked(tmp_path, cell, capsys, step, words):
    """--study took --time-step unchecked: 0 became 1/240 silently, nan ran every trial."""
    _one_line(capsys, _run(['--study', str(_file(tmp_path, _search())), '--time-step', step,
                            '--out', str(tmp_path / 'o')]), words)


def test_a_study_yaml_that_is_a_directory_is_one_line(tmp_path, cell, capsys):
    out = tmp_path / 'o'
    (out / 'study.yaml').mkdir(parents=True)
    _one_line(capsys, _run(['--study', str(_file(tmp_path, _search())), '--out', str(out)]),
              'study.yaml is a directory')
    _one_line(capsys, _run(['--study', str(out / 'study.yaml'), '--out', str(tmp_path / 'p')]),
              'is a directory')


def test_a_sweep_and_a_rerun_refuse_parameters_inside_one_another(tmp_path, cell, capsys):
    _one_line(capsys, _run(['--sweep', 'conveyor=1,2', '--sweep', 'conveyor.length=1,2',
                            '--out', str(tmp_path / 'sweep')]), 'which is a part of it')
    trial = ROOT / 'docs' / 'trials' / 'belt-speed-dense' / 'trial_000'
    out = tmp_path / 'rerun'
    _one_line(capsys, _run(['--rerun', str(trial), '--set', 'conveyor=1', '--set',
                            'conveyor.length=3', '--out', str(out)]), 'which is a part of it')
    assert not out.exists()


@pytest.mark.slow
def test_a_reruns_changed_world_is_checked_as_world_checks_it(tmp_path, cell, capsys):
    """`--rerun --set` skipped the layout check: 1000 oranges started a trial that --world
    refuses in one line; and a refused --set left its --out behind."""
    trial = ROOT / 'docs' / 'trials' / 'belt-speed-dense' / 'trial_000'
    out = tmp_path / 'rerun'
    _one_line(capsys, _run(['--rerun', str(trial), '--set', 'materials.counts.orange=1000',
                            '--out', str(out)]),
              'the world as changed cannot be run', 'slots in reach for 1000 materials')
    assert not out.exists()
    # Into a directory that holds a run already: refused, and nothing of it changed.
    campaign = tmp_path / 'campaign'
    assert _run(['--trials', '1', '--out', str(campaign)]) == 0
    before = (campaign / 'trial_000' / 'result.json').read_bytes()
    _one_line(capsys, _run(['--rerun', str(trial), '--out', str(campaign)]),
              'holds a campaign')
    assert (campaign / 'trial_000' / 'result.json').read_bytes() == before


def test_a_trial_makes_a_campaign_directory_that_is_not_there_yet(tmp_path, monkeypatch):
    """A Ray worker runs its trials in a directory of its own that nothing made before."""
    from studies.trial_process import run_trial
    monkeypatch.setenv('PATH', str(tmp_path / 'nothing_here'))
    out = tmp_path / 'worker' / 'campaign'
    result = run_trial(0, 11, 0.12, 231, out, wall_timeout=5.0)
    assert result.message.startswith('cannot start sim_node')
    assert (out / 'trial_000' / 'result.json').is_file()
