"""Campaign progress and its ETA (coordinator/progress.py)."""
import pytest

from coordinator.progress import (TYPICAL_COMPLETION_S, TrialProgress, eta_seconds,
                                  format_duration, progress_line, read_progress,
                                  write_progress)


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
    write_progress(path, sim_time=12.5, delivered=3, total=8)
    assert read_progress(path) == {'sim_time': 12.5, 'delivered': 3, 'total': 8}
    path.write_text('{"sim_ti')
    assert read_progress(path) is None
    line = progress_line(1, 10, [TrialProgress(3, 42.0, 2, 8, 20.0, 'pick', 'wait_load')], 95.0)
    assert 'trial 3: 42 s sim, 2/8 delivered (pick/wait_load)' in line
    assert line.startswith('[trials] 1/10 done') and line.endswith('ETA 1 min 35 s')
