"""Campaign progress and its ETA (studies/progress.py)."""
import io
import json

import pytest

from studies.progress import (
    TYPICAL_COMPLETION_S,
    CampaignBar,
    TrialProgress,
    eta_seconds,
    format_duration,
    progress_line,
    read_progress,
    running_figures,
)
from trial_record.result import TrialResult


def test_a_running_trial_is_projected_from_its_own_pace():
    # 30 s simulated in 10 s of wall time: 3x; the other 110 s need about 37 s more.
    p = TrialProgress(0, 30.0, 2, 8, 10.0)
    assert eta_seconds([p], [], [], 0, 1) == pytest.approx((TYPICAL_COMPLETION_S - 30) / 3)
    # Finished trials set what a trial needs and what a pending one costs.
    eta = eta_seconds([p], [50.0, 70.0], [60.0, 62.0], pending=4, parallel=2)
    assert eta == pytest.approx((61.0 - 30.0) / 3 + 60.0 * 4 / 2)


def test_nothing_to_estimate_from_gives_no_eta():
    assert eta_seconds([TrialProgress(0, 0.0, 0, 8, 0.0)], [], [], 3, 1) is None
    assert format_duration(None) == '?'
    assert format_duration(59.4) == '59 s' and format_duration(61) == '1 min 01 s'
    assert format_duration(3 * 3600 + 120) == '3 h 02 min'


def test_progress_files_round_trip_and_a_torn_read_is_none(tmp_path):
    path = tmp_path / 'progress.json'
    assert read_progress(path) is None
    path.write_text(json.dumps({'sim_time': 12.5, 'delivered': 3, 'total': 8}))   # (as the node)
    assert read_progress(path) == {'sim_time': 12.5, 'delivered': 3, 'total': 8}
    path.write_text('{"sim_ti')
    assert read_progress(path) is None
    line = progress_line(1, 10, [TrialProgress(3, 42.0, 2, 8, 20.0, 'pick', 'wait_load')], 95.0)
    assert 'trial 3: 42 s sim, 2/8 delivered (pick/wait_load)' in line
    assert line.startswith('[trials] 1/10 done') and line.endswith('ETA 1 min 35 s')


def _result(status='completed', t=60.0, ident=1.0, grasp=1.0, handling=1.0):
    return TrialResult(status, t, identification_rate=ident, grasp_success_rate=grasp,
                       handling_success_rate=handling)


def test_the_running_figures_are_the_campaigns_table_2_so_far():
    assert running_figures([]) == '0 not completed'
    results = [_result(t=58.0), _result(t=62.0, handling=0.875),
               _result('incomplete', t=70.0, grasp=0.9, handling=0.75)]
    assert running_figures(results) == (
        '1 not completed; median 60.0 s; identification 100.0 %, grasp 96.7 %, '
        'handling 87.5 %')
    # A trial with no score (its processes failed) counts as not completed, not in the rates.
    assert running_figures([_result(), TrialResult.failure('error', 'no result')]) \
        == '1 not completed; median 60.0 s; identification 100.0 %, grasp 100.0 %, ' \
        'handling 100.0 %'


def test_the_bar_shows_done_failures_figures_running_trials_and_the_eta(monkeypatch):
    monkeypatch.setenv('COLUMNS', '120')           # (a terminal's width)
    stream = io.StringIO()
    bar = CampaignBar(total=10, done=2, stream=stream)
    bar.update([_result(), _result('incomplete')], [TrialProgress(4, 31.0, 3, 8, 12.0)],
               eta=95.0, finished=1)
    bar.write('[trials] 3/10 trial 4: completed')
    bar.close()
    out = stream.getvalue()
    assert '3/10' in out and '1 failed' in out and 'median 60.0 s' in out
    assert 'ident 100% grasp 100% handling 100%' in out
    assert '#4 31 s' in out and 'ETA 1 min 35 s' in out
    assert '[trials] 3/10 trial 4: completed' in out
