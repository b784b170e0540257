"""The lock-step protocol's two sides (controllers/lockstep.py), without ROS."""
import pytest

from controllers.lockstep import CommandBarrier, CommandCounter, DueGrid, next_on_grid

DT_NS = round(1e9 / 240)


def test_a_step_runs_only_once_its_announced_commands_are_in():
    counter, barrier = CommandCounter(), CommandBarrier()
    counter.sent()
    counter.sent()
    announced = counter.take()
    assert announced == 2 and counter.take() == 0          # each request counts afresh
    # The step request overtook both commands: it must wait for them.
    assert not barrier.ready(announced)
    with pytest.raises(RuntimeError):
        barrier.claim(announced)
    barrier.arrived()
    assert not barrier.ready(announced)
    barrier.arrived()
    assert barrier.ready(announced)
    claim = barrier.claim(announced)
    assert (claim.expected, claim.received, claim.surplus) == (2, 2, 0)
    # The next step starts from zero: a step without commands runs at once.
    assert barrier.received == 0 and barrier.ready(0)


def test_commands_nobody_announced_are_reported_as_surplus():
    barrier = CommandBarrier()
    for _ in range(3):
        barrier.arrived()
    claim = barrier.claim(1)
    assert claim.surplus == 2 and barrier.received == 0


def test_the_due_grid_replays_the_simulators_schedule():
    # The simulator publishes at the first step at or after each multiple of the period
    # (runner.py uses next_on_grid); the controller's grid must name exactly those steps,
    # however the steps are split into batches.
    period = round(1e9 / 30)
    expected, next_ns = [], 0
    for k in range(1, 2001):
        t = k * DT_NS
        if t >= next_ns:
            expected.append(t)
            next_ns = next_on_grid(t, period)
    grid, got, step = DueGrid(DT_NS, period), [], 0
    for batch in [1, 7, 8, 8, 240, 1, 3, 500, 1000, 232]:
        got += grid.advance(step, step + batch)
        step += batch
    assert step == 2000 and got == expected
    # 240 Hz states at a 240 Hz step: every step.
    every = DueGrid(DT_NS, DT_NS)
    assert every.advance(0, 5) == [k * DT_NS for k in range(1, 6)]


def test_a_grid_started_after_the_first_observation_skips_what_was_already_out():
    grid = DueGrid(DT_NS, round(1e9 / 30))
    grid.start_after(8 * DT_NS)
    assert grid.advance(8, 16) == [16 * DT_NS]
    with pytest.raises(ValueError):
        DueGrid(0, 10)
