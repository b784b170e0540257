"""Time-optimal joint motions through waypoints (controllers.time_optimal, on ruckig)."""
import numpy as np
import pytest

from controllers.time_optimal import (JointLimits, PlanError, Waypoint, plan,
                                      rest_to_rest_time)

LIMITS = JointLimits(np.array([2.0, 2.0, 3.0]), np.array([8.0, 8.0, 12.0]),
                     np.array([80.0, 80.0, 120.0]))


def _check_within_limits(motion, limits):
    for s in motion.samples:
        assert np.all(np.abs(s.v) <= limits.velocity + 1e-9)
        assert np.all(np.abs(s.a) <= limits.acceleration + 1e-6)
    # Between samples too: the average speed of every sample interval.
    for a, b in zip(motion.samples, motion.samples[1:]):
        if b.t > a.t:
            assert np.all(np.abs(b.q - a.q) / (b.t - a.t) <= limits.velocity + 1e-9)


def test_a_motion_starts_and_ends_at_rest_at_its_goal_within_the_limits():
    q0, goal = np.zeros(3), np.array([1.5, -0.7, 2.0])
    motion = plan(q0, [Waypoint(goal)], LIMITS, t0=10.0)
    first, last = motion.samples[0], motion.samples[-1]
    assert first.t == 10.0 and np.allclose(first.q, q0) and not np.any(first.v)
    assert np.allclose(last.q, goal) and not np.any(last.v)
    assert motion.end == pytest.approx(10.0 + rest_to_rest_time(q0, goal, LIMITS))
    _check_within_limits(motion, LIMITS)
    # Time-synchronised: every joint arrives at the same time, the slowest at its limit.
    assert max(np.max(np.abs([s.v[0] for s in motion.samples])), 0) == pytest.approx(
        2.0 * 0.98, rel=0.01)


def test_passing_through_a_via_point_is_faster_than_stopping_there():
    q0, via, goal = np.zeros(3), np.array([1.0, 0.5, 0.0]), np.array([2.0, 1.0, 0.5])
    through = plan(q0, [Waypoint(via, stop=False), Waypoint(goal)], LIMITS)
    stopping = plan(q0, [Waypoint(via), Waypoint(goal)], LIMITS)
    assert through.end < stopping.end - 0.1
    (t_via, _) = through.arrivals[0], through.arrivals[1]
    at_via = next(s for s in through.samples if s.t == t_via)
    assert np.allclose(at_via.q, via) and np.any(at_via.v)     # passed, not stopped at
    _check_within_limits(through, LIMITS)


def test_a_joint_that_turns_back_at_a_via_point_stops_there():
    q0, via, goal = np.zeros(3), np.array([1.0, 1.0, 0.0]), np.array([2.0, 0.0, 0.0])
    motion = plan(q0, [Waypoint(via, stop=False), Waypoint(goal)], LIMITS)
    at_via = next(s for s in motion.samples if s.t == motion.arrivals[0])
    assert at_via.v[1] == 0.0 and at_via.v[0] > 0.0


def test_holds_and_minimum_segment_times_are_kept():
    q0, goal = np.zeros(3), np.array([0.01, 0.0, 0.0])
    motion = plan(q0, [Waypoint(goal, hold=0.5, min_time=0.3)], LIMITS, t0=1.0)
    assert motion.arrivals == [pytest.approx(1.3)]
    assert motion.end == pytest.approx(1.8)
    assert np.allclose(motion.samples[-1].q, goal) and np.allclose(motion.samples[-2].q, goal)


def test_a_waypoint_where_the_arm_already_is_adds_nothing_but_its_hold():
    q = np.array([0.5, 0.5, 0.5])
    motion = plan(q, [Waypoint(q.copy(), stop=False), Waypoint(q.copy(), hold=0.2)], LIMITS)
    times = [s.t for s in motion.samples]
    assert times == [0.0, pytest.approx(0.2)]


def test_samples_are_dense_and_increasing():
    motion = plan(np.zeros(3), [Waypoint(np.array([3.0, 0.0, 0.0]))], LIMITS)
    times = [s.t for s in motion.samples]
    assert all(b > a for a, b in zip(times, times[1:]))
    assert max(np.diff(times)) <= 0.05 + 1e-9


@pytest.mark.parametrize('waypoints, limits', [
    ([], LIMITS),
    ([Waypoint(np.array([1.0, np.nan, 0.0]))], LIMITS),
    ([Waypoint(np.array([1.0, 0.0]))], LIMITS),
    ([Waypoint(np.ones(3))], JointLimits(np.array([2.0, 0.0, 1.0]), LIMITS.acceleration,
                                         LIMITS.jerk)),
    ([Waypoint(np.ones(3))], JointLimits(LIMITS.velocity, np.array([1.0, np.inf, 1.0]),
                                         LIMITS.jerk)),
])
def test_bad_waypoints_or_limits_are_refused(waypoints, limits):
    with pytest.raises(PlanError):
        plan(np.zeros(3), waypoints, limits)


def test_a_velocity_scaling_outside_0_1_is_refused():
    with pytest.raises(PlanError):
        LIMITS.scaled(1.5)
    assert np.allclose(LIMITS.scaled(0.5).velocity, LIMITS.velocity / 2)
