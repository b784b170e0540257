"""bench/goals.py: the issue-12 table takes only the figures of the run it ends."""
import importlib.util
import json
import os
from pathlib import Path

GOALS = Path(__file__).resolve().parents[2] / 'bench' / 'goals.py'


def _goals():
    spec = importlib.util.spec_from_file_location('bench_goals', GOALS)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_goals_are_judged_on_this_runs_figures_only(tmp_path):
    goals = _goals()
    (tmp_path / 'bench_pipeline.json').write_text(json.dumps({
        'cpu_cut_vs_filed': 3.2, 'ratio_rtf_vs_in_process': 0.4,
        'single_run': {'wall_seconds': 14.0}, 'parallel_speedup': 1.5,
        'parallel_2': {'trials_per_hour': 360.0}}))
    (tmp_path / 'bench_kinematics.json').write_text(json.dumps({
        'fk_us': {'youbot': 6.0, 'zu12': 21.0}, 'youbot_ik_per_s': 25000.0,
        'zu12_ik_median_ms': 0.07}))
    old = tmp_path / 'bench_recorder.json'           # from an earlier run
    old.write_text(json.dumps({'summary': {'640x480 project': {'ratio': 0.9,
                                                               'drain_ratio': 0.9}}}))
    os.utime(old, (1000.0, 1000.0))
    table = {label: (value, met) for label, _, value, _, met in
             goals.rows(since=2000.0, results=tmp_path)}
    assert table['CPU per simulated second, the nodes measured when filed: cut'] == (3.2, True)
    assert table['node graph / in-process baseline (real-time factors)'] == (0.4, False)
    assert table['wall time of one trial'] == (14.0, True)
    assert table['two trials at a time / one at a time (throughput)'] == (1.5, False)
    assert table['110 trials two at a time (from that throughput)'] == (
        110 * 60.0 / 360.0, True)
    assert table['make study, 28 trials two at a time (from that throughput)'] == (
        28 * 60.0 / 360.0, True)
    assert table['FK, the slower arm'] == (21.0, False)
    assert table['Zu 12 IK, median'] == (0.07, True)
    # The recorder's figures are older than the run: not used, not judged.
    assert table['recorder / raw rosbags write, 640x480, streaming'] == (None, None)
