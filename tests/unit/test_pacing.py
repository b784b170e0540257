"""Real-time pacing and the real-time factor meter."""
import pytest

from sim_bridge.pacing import Pacer, RtfMeter

DT = 1.0 / 240.0


def test_real_time_schedule():
    pacer = Pacer(DT, 1.0)
    assert pacer.steps_due(100.0) == 0
    due = pacer.steps_due(100.0 + 10 * DT)
    assert due == 10
    pacer.record(due)
    assert pacer.steps_due(100.0 + 10.5 * DT) == 0
    assert pacer.wall_until_next(100.0 + 10.5 * DT) == pytest.approx(0.5 * DT)


def test_faster_than_real_time():
    pacer = Pacer(DT, 4.0, max_burst=200)
    pacer.steps_due(0.0)
    assert pacer.steps_due(0.1) == 96


def test_falling_behind_is_bounded_and_reanchored():
    pacer = Pacer(DT, 1.0, max_burst=16)
    pacer.steps_due(0.0)
    assert pacer.steps_due(10.0) == 16   # a 10 s stall is not 2400 catch-up steps
    pacer.record(16)
    assert pacer.steps_due(10.0) == 0
    assert pacer.steps_due(10.0 + 2 * DT) == 2


def test_as_fast_as_possible_gives_bursts():
    pacer = Pacer(DT, 0.0, max_burst=8)
    assert pacer.as_fast_as_possible
    assert pacer.steps_due(0.0) == 8 and pacer.wall_until_next(0.0) == 0.0


def test_restart_forgets_the_schedule():
    pacer = Pacer(DT, 1.0)
    pacer.steps_due(0.0)
    pacer.restart()
    assert pacer.steps_due(50.0) == 0


@pytest.mark.parametrize('args', [(0.0, 1.0), (DT, -1.0), (DT, float('inf')), (DT, 1.0, 0)])
def test_bad_arguments(args):
    with pytest.raises(ValueError):
        Pacer(*args)


def test_rtf_meter_window():
    meter = RtfMeter(window=5.0)
    assert meter.value() is None
    for i in range(100):
        meter.add(i * 0.1, i * 0.2)
    assert meter.value() == pytest.approx(2.0)
