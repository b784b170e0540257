"""run_trials --rerun on a recorded run, as a user runs it: without a change the trial runs
again the same to the last event, from its bag alone too; with --set belt_speed it differs, and
says where. The recorded run's storyboard is drawn from its bag."""
import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np

from studies.recorded import result_from_bag
from studies.storyboard import CAPTION, PANEL
from trial_record.result import read_result

SHORT_CELL = '''extends: package://world_description/worlds/pipeline_cell.yaml
materials:
  counts: {purple: 1, orange: 2, blue: 0}
'''


def _run(*args, timeout=600):
    return subprocess.run([shutil.which('run_trials'), *map(str, args), '--bar', 'off'],
                          capture_output=True, text=True, timeout=timeout)


def _start(*args):
    """run_trials started with ``args``, printing into files beside its output directory."""
    out = Path(str(args[args.index('--out') + 1]))
    sinks = [open(f'{out}.{name}', 'w+') for name in ('stdout', 'stderr')]
    proc = subprocess.Popen([shutil.which('run_trials'), *map(str, args), '--bar', 'off'],
                            stdout=sinks[0], stderr=sinks[1], text=True)
    return proc, sinks


def _finished(started, timeout=600):
    """A started run's end, as subprocess.run returns it."""
    proc, sinks = started
    try:
        proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    printed = []
    for sink in sinks:
        sink.seek(0)
        printed.append(sink.read())
        sink.close()
    return subprocess.CompletedProcess(proc.args, proc.returncode, *printed)


def test_a_rerun_is_the_same_run_and_a_changed_one_differs_where_it_should(tmp_path):
    world = tmp_path / 'short_cell.yaml'
    world.write_text(SHORT_CELL)
    first = _run('--seeds', '5', '--belt-speed', '0.12', '0.12', '--world', world, '--record',
                 '--out', tmp_path / 'demo')
    assert first.returncode == 0, first.stdout + first.stderr
    original, _ = read_result(tmp_path / 'demo' / 'trial_000' / 'result.json')
    assert original.status == 'completed' and original.scenario['world_data']['materials']
    world.unlink()              # (the re-run needs nothing but the recorded run)
    # The bag alone keeps the run: what ran (its metadata) and how it went (the coordinator's
    # last state).
    bag = tmp_path / 'elsewhere' / 'run'
    shutil.copytree(tmp_path / 'demo' / 'trial_000' / 'bag', bag)
    kept = result_from_bag(bag)
    assert kept.differences(original) == []
    assert json.dumps(kept.scenario) == json.dumps(original.scenario)     # (order included)
    _storyboard_shows_the_run(tmp_path / 'demo', original)

    # The two re-runs at once (lock-step: a trial does not depend on the machine's load; each
    # leases a DDS domain of its own).
    started = [_start('--rerun', bag, '--out', tmp_path / 'same'),
               _start('--rerun', tmp_path / 'demo' / 'trial_000', '--set', 'belt_speed=0.2',
                      '--out', tmp_path / 'faster')]
    same, faster = (_finished(p) for p in started)
    assert same.returncode == 0, same.stdout + same.stderr
    assert 'the same run as the original' in same.stdout
    again, _ = read_result(tmp_path / 'same' / 'trial_000' / 'result.json')
    assert again.differences(original) == []
    assert again.events == original.events and again.final_materials == original.final_materials

    assert faster.returncode == 0, faster.stdout + faster.stderr
    changed, _ = read_result(tmp_path / 'faster' / 'trial_000' / 'result.json')
    assert changed.belt_speed == 0.2 and changed.parameters == {'belt_speed': 0.2}
    assert 'differs from the original in' in faster.stdout and 'events' in faster.stdout
    assert 'first: event' in faster.stdout
    # The same materials in the same order; what the belt does with them changes the times.
    assert [m['color'] for m in changed.final_materials] == \
        [m['color'] for m in original.final_materials]
    assert changed.events[0] == original.events[0]          # (the belt starts as before)
    assert changed.events != original.events

    bad = _run('--rerun', tmp_path / 'demo', '--set', 'perturbations.camera.blurr=1',
               '--out', tmp_path / 'bad')
    assert bad.returncode == 2 and "unknown keys ['blurr']" in bad.stderr


def _storyboard_shows_the_run(run, original):
    """The report links the storyboard of the recorded trial: a picture per phase."""
    assert '![storyboard](storyboard.png)' in (run / 'report.md').read_text()
    img = cv2.imread(str(run / 'storyboard.png'))
    kinds = {e[1] for e in original.events}
    expected = 1 + len(kinds & {'picked', 'loaded', 'placed', 'departing', 'loading_over',
                                'delivered', 'finished'})
    assert expected == 8                  # (the short cell has every phase)
    h, w = PANEL[1] + CAPTION + 6, PANEL[0] + 6
    assert img.shape == (40 + 2 * h, 4 * w, 3)
    first, last = (img[40 + CAPTION:40 + h - 6, :PANEL[0]].astype(int),
                   img[40 + h + CAPTION:40 + 2 * h - 6, 3 * w:3 * w + PANEL[0]].astype(int))
    # At the start and with both robots home the cell differs: the materials were moved.
    assert (np.abs(first - last).sum(axis=2) > 30).mean() > 0.001
