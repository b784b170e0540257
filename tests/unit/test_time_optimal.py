"""Time-optimal joint motions through waypoints (controllers.time_optimal, on ruckig)."""
import numpy as np
import pytest

from controllers.pick_place import PickTiming, follow_pick
from controllers.time_optimal import (
    JointLimits,
    PlanError,
    TooLate,
    Waypoint,
    plan,
    rest_to_rest_time,
    timed_path,
)

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


def test_the_speed_at_a_via_point_is_chosen_for_the_shortest_motion(monkeypatch):
    # Two long moves in the same direction: the average-speed guess at the via point is slow,
    # a faster pass is quicker, and the motion stays within the limits.
    import controllers.time_optimal as time_optimal
    q0, via, goal = np.zeros(3), np.array([1.0, 0.4, 0.2]), np.array([3.0, 1.2, 0.6])
    chosen = plan(q0, [Waypoint(via, stop=False), Waypoint(goal)], LIMITS)
    monkeypatch.setattr(time_optimal, 'VIA_SCALES', (1.0,))
    guessed = plan(q0, [Waypoint(via, stop=False), Waypoint(goal)], LIMITS)
    assert chosen.end < guessed.end - 0.05
    _check_within_limits(chosen, LIMITS)
    at_via = next(s for s in chosen.samples if s.t == chosen.arrivals[0])
    assert np.allclose(at_via.q, via) and np.all(np.abs(at_via.v) <= 0.9 * LIMITS.velocity)


def test_a_motion_may_start_moving_and_comes_to_rest_at_its_goal():
    q0, v0, a0 = np.zeros(3), np.array([1.5, -0.5, 0.0]), np.array([2.0, 0.0, -1.0])
    goal = np.array([0.1, 0.1, 0.0])
    motion = plan(q0, [Waypoint(goal)], LIMITS, t0=2.0, v0=v0, a0=a0)
    first, last = motion.samples[0], motion.samples[-1]
    assert first.t == 2.0 and np.allclose(first.v, v0) and np.allclose(first.a, a0)
    assert np.allclose(last.q, goal) and not np.any(last.v)
    _check_within_limits(motion, LIMITS)
    # Joint 1 overshoots its goal (it cannot stop in time) and comes back.
    assert max(s.q[0] for s in motion.samples) > goal[0]
    with pytest.raises(PlanError):
        plan(q0, [Waypoint(goal)], LIMITS, v0=[1.0, np.nan, 0.0])


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


def test_a_timed_waypoint_is_met_at_its_time_with_its_velocity_then_a_path_is_followed():
    # Meeting something moving: at t = 3 s at q1 moving at v1, then along samples as given.
    q1, v1 = np.array([1.0, -0.5, 0.3]), np.array([0.2, 0.0, -0.1])
    follow = [Waypoint(q1 + v1 * dt, velocity=v1, at=3.0 + dt, direct=True)
              for dt in (0.05, 0.1, 0.15)]
    motion = plan(np.zeros(3), [Waypoint(q1, velocity=v1, at=3.0)] + follow
                  + [Waypoint(q1 + v1 * 0.15 + np.array([0.0, 0.3, 0.0]))], LIMITS, t0=1.0)
    met = [s for s in motion.samples if s.t == pytest.approx(3.0)]
    assert met and np.allclose(met[0].q, q1) and np.allclose(met[0].v, v1)
    for w in follow:
        s, = [s for s in motion.samples if s.t == pytest.approx(w.at)]
        assert np.allclose(s.q, w.q) and np.allclose(s.v, w.velocity)
    assert motion.arrivals[:4] == pytest.approx([3.0, 3.05, 3.1, 3.15])
    assert not np.any(motion.samples[-1].v)
    _check_within_limits(motion, LIMITS)


def test_a_timed_waypoint_the_arm_cannot_make_is_too_late():
    far = np.array([3.0, 0.0, 0.0])          # 1.5 s at least at 2 rad/s
    with pytest.raises(TooLate):
        plan(np.zeros(3), [Waypoint(far, velocity=np.zeros(3), at=1.0), Waypoint(far)],
             LIMITS, t0=0.0)


@pytest.mark.parametrize('bad', [
    dict(velocity=np.array([5.0, 0.0, 0.0])),                  # beyond the velocity limit
    dict(velocity=np.zeros(3), acceleration=np.array([0.0, 20.0, 0.0])),
    dict(velocity=np.array([np.nan, 0.0, 0.0])),
])
def test_a_given_state_beyond_the_limits_is_refused(bad):
    with pytest.raises(PlanError):
        plan(np.zeros(3), [Waypoint(np.ones(3), at=2.0, **bad), Waypoint(np.ones(3) * 1.2)],
             LIMITS)


def test_a_motion_cannot_end_moving_and_a_direct_waypoint_needs_its_time():
    with pytest.raises(PlanError, match='ends at rest'):
        plan(np.zeros(3), [Waypoint(np.ones(3), velocity=np.full(3, 0.1))], LIMITS)
    with pytest.raises(PlanError, match='direct'):
        plan(np.zeros(3), [Waypoint(np.ones(3), direct=True), Waypoint(np.ones(3))], LIMITS)


def test_the_pick_path_moves_with_the_material_while_on_it():
    speed = np.array([0.12, 0.0, 0.0])
    track = lambda t: np.array([-0.5, 0.75, 0.425]) + speed * t      # noqa: E731
    timing = PickTiming(hover=0.06, descend=0.3, dwell=0.15, lift=0.3, lift_height=0.12)
    path, lift = follow_pick(track, 5.0, 0.05, timing, period=0.05)
    times = [t for t, _ in path]
    assert times[0] == pytest.approx(4.7) and times[-1] == pytest.approx(5.15)
    assert np.all(np.diff(times) <= 0.05 + 1e-12)
    top = 0.425 + 0.025
    heights = [p[2] - top for _, p in path]
    assert heights[0] == pytest.approx(0.06) and np.all(np.diff(heights) <= 1e-12)
    for t, p in path:
        assert p[:2] == pytest.approx(track(t)[:2])          # right over it, all along
        if t >= 5.0:
            assert p[2] == pytest.approx(top)                # on its top face from contact
    # The lift point: the lift's height over the contact, ahead by half the travel of the lift.
    assert lift == pytest.approx(track(5.15) + np.array([0.12 * 0.15, 0.0, 0.025 + 0.12]))


def test_a_brake_comes_to_rest_from_a_moving_state_without_going_back():
    from controllers.time_optimal import brake
    v = np.array([1.0, -0.5, 0.0])
    motion = brake(np.zeros(3), v, np.zeros(3), LIMITS, 3.0)
    points = motion.points()
    assert points[0][0] == 3.0 and not np.any(points[-1][2])
    # Each joint ends where it brakes to, hardly coming back (the joints end together: one
    # braked more gently than it could may come back by a fraction of a milliradian).
    qs = np.array([p[1] for p in points])
    assert np.all(np.diff(qs[:, 0]) >= -1e-3) and np.all(np.diff(qs[:, 1]) <= 1e-3)
    assert np.max(qs[:, 0]) - qs[-1, 0] < 1e-3 and qs[-1, 1] - np.min(qs[:, 1]) < 1e-3
    acc, jerk = LIMITS.acceleration, LIMITS.jerk
    assert qs[-1] == pytest.approx(v * (np.abs(v) / (2 * acc) + acc / (2 * jerk)), abs=1e-6)


def test_the_lift_point_stays_behind_the_end_stop_that_holds_the_material():
    """Met just before an end stop on a fast belt, the lift point is no further ahead than
    where the stop holds the material: half the lift's travel would put it past the stop's
    wall, and the cup would drag the material into it."""
    stop_x = 0.675
    track = lambda t: np.array([min(0.62 + 0.36 * (t - 5.0), stop_x), 0.75, 0.425])  # noqa: E731
    timing = PickTiming(hover=0.06, descend=0.3, dwell=0.14, lift=0.2, lift_height=0.07)
    path, lift = follow_pick(track, 5.0, 0.05, timing, period=0.05)
    assert path[-1][1][0] < stop_x                   # still carried at the end of the dwell
    assert lift[0] == pytest.approx(stop_x)          # (unclamped: 0.6704 + 0.036 = 0.706)
    # Carried freely past the lift, the lead is the same as before.
    free = lambda t: np.array([0.62 + 0.36 * (t - 5.0), 0.75, 0.425])  # noqa: E731
    assert follow_pick(free, 5.0, 0.05, timing)[1][0] == pytest.approx(
        free(5.14)[0] + 0.36 * 0.1)


def _curve(s):
    """A curved joint-space path (a tool's straight line is one for a real arm)."""
    s = np.asarray(s, float)
    return np.stack([0.8 * s, 0.3 * np.sin(1.5 * s), -0.6 * s + 0.3 * s**2], -1)


@pytest.mark.parametrize('end_speed', [0.0, 0.5, 1.0])
def test_a_timed_path_keeps_to_its_points_line_within_the_limits(end_speed):
    """Through the path's points and on the smooth line between them, not a joint-space
    chord; from rest, within the limits (between samples too), at rest or moving on at the
    end; and on to a next waypoint from there."""
    points = _curve(np.linspace(0.0, 1.0, 7))
    path = timed_path(points, LIMITS, t0=5.0, end_speed=end_speed, min_time=0.1)
    assert all(w.direct for w in path) and path[0].at > 5.0
    assert np.allclose(path[-1].q, points[-1], atol=1e-6)
    moving = np.linalg.norm(path[-1].velocity)
    assert moving == 0.0 if end_speed == 0.0 else moving > 0.1
    goal = np.array([1.0, 0.0, 0.0])
    motion = plan(points[0], path + [Waypoint(goal)], LIMITS, t0=5.0)
    _check_within_limits(motion, LIMITS)
    on_path = [s for s in motion.samples if s.t <= path[-1].at + 1e-9]
    fine = np.linspace(0.0, 1.0, 2001)
    line = _curve(fine)
    for s in on_path:
        assert np.min(np.linalg.norm(line - s.q, axis=1)) < 1e-3  # (a cubic fit; a chord: 0.05)
    # Monotonic along the line: the first joint only rises.
    assert all(b.q[0] >= a.q[0] - 1e-9 for a, b in zip(on_path, on_path[1:]))
    assert np.allclose(motion.samples[-1].q, goal)


def test_a_timed_path_is_not_much_slower_than_a_joint_motion_between_its_ends():
    s = np.linspace(0.0, 1.0, 7)[:, None]
    points = np.hstack([0.5 * s, -0.45 * s + 0.1 * s**2, 0.45 * s + 0.05 * s**2])
    along = timed_path(points, LIMITS, t0=0.0)[-1].at
    assert along < 1.3 * rest_to_rest_time(points[0], points[-1], LIMITS)


@pytest.mark.parametrize('points, speed', [([[0.0, 0.0, 0.0]], 0.0),
                                           ([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]], 0.0),
                                           ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], 1.5)])
def test_a_timed_path_refuses_bad_points_or_speeds(points, speed):
    with pytest.raises(PlanError):
        timed_path(points, LIMITS, t0=0.0, end_speed=speed)
