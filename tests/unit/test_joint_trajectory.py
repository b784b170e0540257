"""Trajectory validation (every rejection rule) and interpolation of the joint-group follower."""
import math

import numpy as np
import pytest

from controllers.joint_trajectory import (
    JointLimits,
    TrajectoryFollower,
    TrajectoryPoint,
    TrajectoryRequest,
)

NAMES = ('j1', 'j2', 'j3')
LIMITS = JointLimits(lower=np.array([-2.0, -1.0, -3.0]), upper=np.array([2.0, 1.5, 3.0]),
                     velocity=np.array([1.0, 1.0, 2.0]), effort=np.array([5.0, 5.0, 1.0]))


def follower(q=(0.0, 0.0, 0.0)):
    return TrajectoryFollower(NAMES, LIMITS, q)


def request(points, names=NAMES, start=None):
    return TrajectoryRequest(tuple(names), tuple(TrajectoryPoint(*p) for p in points), start)


GOOD = [(1.0, (0.5, 0.5, 0.5)), (2.0, (1.0, 0.0, -1.0))]


def test_a_good_trajectory_is_accepted_and_reaches_its_waypoints():
    f = follower()
    assert f.set_trajectory(request(GOOD), now=10.0).accepted
    assert f.sample(10.0).positions == pytest.approx([0.0, 0.0, 0.0])
    assert f.sample(11.0).positions == pytest.approx([0.5, 0.5, 0.5])
    end = f.sample(12.0)
    assert end.positions == pytest.approx([1.0, 0.0, -1.0])
    assert end.velocities == pytest.approx([0.0, 0.0, 0.0])
    assert f.sample(20.0).positions == pytest.approx([1.0, 0.0, -1.0])
    assert f.finished(12.0) and not f.finished(11.9)


@pytest.mark.parametrize('req, reason', [
    (request(GOOD, names=()), 'no joint names'),
    (request([(1.0, (0.1, 0.1, 0.1))], names=('j1', 'j2', 'elbow')), "unknown joints ['elbow']"),
    (request([(1.0, (0.1, 0.1, 0.1))], names=('j1', 'j1', 'j2')), "duplicate joint names ['j1']"),
    (request([]), 'empty trajectory'),
    (request([(1.0, (0.1, 0.1))]), 'point 0: 2 positions for 3 joints'),
    (request([(1.0, (0.1, 0.1, 0.1), (0.0, 0.0))]), 'point 0: 2 velocities for 3 joints'),
    (request([(1.0, (0.1, 0.1, 0.1), (0.0,) * 3, (0.0,))]), '1 accelerations for 3 joints'),
    (request([(1.0, (0.1, 0.1, 0.1)), (1.0, (0.2, 0.2, 0.2))]), 'point 1: time_from_start 1 s '
                                                                'is not after'),
    (request([(2.0, (0.1, 0.1, 0.1)), (1.0, (0.2, 0.2, 0.2))]), 'is not after'),
    (request([(-1.0, (0.1, 0.1, 0.1))]), 'is negative'),
    (request([(1.0, (math.nan, 0.1, 0.1))]), 'point 0: non-finite positions'),
    (request([(1.0, (0.1, 0.1, 0.1), (0.0, math.inf, 0.0))]), 'non-finite velocities'),
    (request([(math.inf, (0.1, 0.1, 0.1))]), 'non-finite time_from_start'),
    (request([(1.0, (0.1, 1.6, 0.1))]), 'point 0: j2 target 1.6000 is outside its limits'),
    (request([(1.0, (-2.5, 0.0, 0.0))]), 'j1 target -2.5000 is outside'),
    (request([(1.0, (0.1, 0.1, 0.1), (0.0, 1.5, 0.0))]), 'j2 velocity 1.5000 exceeds'),
    (request([(0.0, (0.5, 0.0, 0.0))]), 'needs a time_from_start > 0'),
    (request([(0.5, (1.0, 0.0, 0.0))]), 'j1 would move 0.8000 in 0.500 s'),
    (request([(1.0, (0.1, 0.1, 0.1)), (2.0, (0.2, 0.2, 0.2), (0.0,) * 3)]),
     'velocities given for some points but not all'),
    (request(GOOD, start=5.0), 'trajectory ends at 7.000 s, before now (10.000 s)'),
])
def test_rejections_name_the_reason_and_leave_the_hold_untouched(req, reason):
    f = follower((0.2, 0.1, 0.0))
    result = f.set_trajectory(req, now=10.0)
    assert not result.accepted
    assert reason in result.reason
    assert not f.active
    assert f.sample(11.0).positions == pytest.approx([0.2, 0.1, 0.0])


def test_a_point_at_time_zero_is_fine_when_it_is_where_the_joint_is():
    f = follower((0.2, 0.1, 0.0))
    assert f.set_trajectory(request([(0.0, (0.2, 0.1, 0.0)), (1.0, (0.3, 0.1, 0.0))]),
                            now=1.0).accepted
    assert f.sample(2.0).positions == pytest.approx([0.3, 0.1, 0.0])


def test_partial_joint_sets_hold_the_joints_left_out():
    f = follower((0.2, 0.1, -0.4))
    assert f.set_trajectory(request([(1.0, (0.9,))], names=('j1',)), now=0.0).accepted
    for t in np.linspace(0.0, 1.5, 16):
        s = f.sample(t)
        assert s.positions[1:] == pytest.approx([0.1, -0.4])
    assert f.sample(1.0).positions[0] == pytest.approx(0.9)


def test_a_new_trajectory_replaces_the_active_one_without_a_jump():
    f = follower()
    f.set_trajectory(request([(2.0, (1.0, 1.0, 1.0))]), now=0.0)
    mid = f.sample(1.0)
    assert 0.1 < mid.positions[0] < 0.9 and mid.velocities[0] > 0.1
    assert f.set_trajectory(request([(2.0, (-1.0, -0.5, 0.0))]), now=1.0).accepted
    after = f.sample(1.0)
    assert after.positions == pytest.approx(mid.positions)
    assert after.velocities == pytest.approx(mid.velocities)
    assert f.sample(3.0).positions == pytest.approx([-1.0, -0.5, 0.0])


def test_interpolation_is_smooth_and_never_overshoots_monotone_waypoints():
    f = follower()
    points = [(0.5, (0.2, 0.0, 0.0)), (1.0, (0.3, 0.0, 0.0)), (1.5, (0.8, 0.0, 0.0)),
              (3.0, (0.8, 0.0, 0.0)), (4.0, (0.1, 0.0, 0.0))]
    assert f.set_trajectory(request(points), now=0.0).accepted
    ts = np.linspace(0.0, 4.0, 4001)
    q = np.array([f.sample(t).positions[0] for t in ts])
    v = np.array([f.sample(t).velocities[0] for t in ts])
    assert q.min() >= -1e-12 and q.max() <= 0.8 + 1e-12          # never beyond the waypoints
    assert np.all(np.diff(q[ts <= 1.5]) >= -1e-12)                 # rising part stays rising
    # Velocity is continuous at every knot (cubic Hermite with shared knot slopes) ...
    for knot in (0.5, 1.0, 1.5, 3.0):
        before, after = f.sample(knot - 1e-9).velocities[0], f.sample(knot + 1e-9).velocities[0]
        assert before == pytest.approx(after, abs=1e-6)
    # ... and matches the derivative of the position.
    assert np.gradient(q, ts)[1:-1] == pytest.approx(v[1:-1], abs=6e-3)


def test_given_velocities_and_accelerations_are_honoured_quintic():
    f = follower()
    pts = [(1.0, (0.5, 0.0, 0.0), (0.3, 0.0, 0.0), (0.1, 0.0, 0.0)),
           (2.0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))]
    assert f.set_trajectory(request(pts), now=0.0).accepted
    s = f.sample(1.0)
    assert s.positions[0] == pytest.approx(0.5)
    assert s.velocities[0] == pytest.approx(0.3)
    assert s.accelerations[0] == pytest.approx(0.1)


def test_a_future_stamp_holds_until_the_start():
    f = follower()
    assert f.set_trajectory(request([(1.0, (0.5, 0.0, 0.0))], start=5.0), now=2.0).accepted
    assert f.sample(4.9).positions == pytest.approx([0.0, 0.0, 0.0])
    assert f.sample(6.0).positions == pytest.approx([0.5, 0.0, 0.0])


def test_a_past_stamp_skips_the_points_already_past():
    f = follower()
    req = request([(1.0, (0.2, 0.0, 0.0)), (4.0, (0.9, 0.0, 0.0))], start=8.0)
    assert f.set_trajectory(req, now=10.0).accepted      # point 0 was due at 9 s: skipped
    assert f.sample(10.0).positions == pytest.approx([0.0, 0.0, 0.0])
    assert f.sample(12.0).positions == pytest.approx([0.9, 0.0, 0.0])


def test_hold_stops_the_trajectory():
    f = follower()
    f.set_trajectory(request(GOOD), now=0.0)
    f.hold([0.1, 0.2, 0.3])
    assert not f.active
    assert f.sample(1.0).positions == pytest.approx([0.1, 0.2, 0.3])


def test_inconsistent_limits_are_a_configuration_error():
    with pytest.raises(ValueError):
        JointLimits(np.zeros(2), np.ones(3), np.ones(2), np.ones(2))
    with pytest.raises(ValueError):
        JointLimits(np.ones(2), np.zeros(2), np.ones(2), np.ones(2))
    with pytest.raises(ValueError):
        TrajectoryFollower(('a', 'a'), JointLimits(np.zeros(2), np.ones(2), np.ones(2),
                                                   np.ones(2)), (0.0, 0.0))


def test_a_motion_that_continues_the_running_one_is_joined_where_it_has_the_arm():
    """A controller takes a new motion a little after it was sent. A motion that begins at a
    sample of the running one, stamped in the future, is refused: until its stamp the
    controller holds where the arm was when it arrived, and from there the sample is out of
    reach. Stamped when it was decided and repeating the running motion's samples until the
    new part, it is joined where the running motion has the arm (its past points skipped)."""
    f = follower()
    times = np.arange(0.0, 2.05, 0.05)
    samples = [(float(t), (0.9 * t, 0.0, 0.0), (0.9, 0.0, 0.0), (0.0, 0.0, 0.0))
               for t in times[1:]]
    assert f.set_trajectory(request(samples, start=0.0), now=0.0).accepted
    # Decided at 0.5 s: from the sample at 0.8 s, to rest at 0.9 rad by 1.8 s.
    stop = [(0.8, (0.72, 0.0, 0.0), (0.9, 0.0, 0.0), (0.0, 0.0, 0.0)),
            (1.8, (0.9, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))]
    late = f.sample(0.75)
    from_rest = request([(t - 0.8 + 0.05, *rest) for t, *rest in stop], start=0.75)
    refused = follower()
    refused.set_trajectory(request(samples, start=0.0), now=0.0)
    assert not refused.set_trajectory(from_rest, now=0.75 - 0.05).accepted   # 0.65 s from 0.7 s
    kept = [p for p in samples if 0.5 < p[0] < 0.8 - 1e-9]
    req = request([(t - 0.5, *rest) for t, *rest in kept + stop], start=0.5)
    assert f.set_trajectory(req, now=0.74).accepted          # arrives 0.24 s after it was sent
    for t in np.arange(0.74, 0.8, 0.01):                     # still on the running motion
        assert f.sample(float(t)).positions[0] == pytest.approx(0.9 * t, abs=1e-6)
    assert late.positions[0] == pytest.approx(0.675)
    end = f.sample(1.8)
    assert end.positions[0] == pytest.approx(0.9) and end.velocities[0] == pytest.approx(0.0)
    speeds = [abs(f.sample(float(t)).velocities[0]) for t in np.arange(0.74, 1.8, 0.01)]
    assert max(speeds) <= LIMITS.velocity[0] + 1e-9


ACCEL = JointLimits(lower=LIMITS.lower, upper=LIMITS.upper, velocity=LIMITS.velocity,
                    effort=LIMITS.effort, acceleration=np.array([6.0, 6.0, 12.0]))


@pytest.mark.parametrize('points, reason', [
    # Issue 15, finding 1: all at rest except the first point's accelerations (finite).
    ([(1.0, (0.0,) * 3, (0.0,) * 3, (1e308,) * 3), (2.0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3)],
     'point 0: j1 acceleration 1e+308 exceeds its limit 6'),
    # Every waypoint at the current position, accelerations 1e3: drove the reference 17 rad off.
    ([(1.0, (0.0,) * 3, (0.0,) * 3, (1e3,) * 3), (2.0, (0.0,) * 3, (0.0,) * 3, (-1e3,) * 3)],
     'point 0: j1 acceleration 1000 exceeds its limit 6'),
    ([(1.0, (0.1, 0.1, 0.1), (0.0,) * 3, (0.0, 0.0, -12.5))], 'j3 acceleration 12.5 exceeds'),
])
def test_accelerations_above_the_limits_are_refused(points, reason):
    f = TrajectoryFollower(NAMES, ACCEL, (0.0, 0.0, 0.0))
    result = f.set_trajectory(request(points), now=0.0)
    assert not result.accepted and reason in result.reason
    assert not f.active and f.sample(1.0).positions == pytest.approx([0.0, 0.0, 0.0])


def test_an_interpolation_that_leaves_the_limits_or_overflows_is_refused():
    f = TrajectoryFollower(NAMES, ACCEL, (0.0, 0.0, 0.0))
    # Allowed velocities and accelerations, but quintics from rest at 0 to rest at 1.4
    # through a velocity of -1 at t = 10 s swing j2 to -1.56, below its lower limit -1.
    swing = [(10.0, (0.7, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 0.0)),
             (20.0, (1.4, 1.4, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))]
    result = f.set_trajectory(request(swing), now=0.0)
    assert not result.accepted
    assert 'the interpolated j2 reaches' in result.reason and 'outside its limits' in result.reason
    # Without acceleration limits, 1e308 passes the point checks and overflows.
    g = follower()
    huge = [(1.0, (0.0,) * 3, (0.0,) * 3, (1e308,) * 3), (2.0, (0.0,) * 3, (0.0,) * 3,
                                                            (0.0,) * 3)]
    result = g.set_trajectory(request(huge), now=0.0)
    assert not result.accepted and 'overflows floating point' in result.reason
    assert not g.active
    # A good one is still taken, and limits at the edge are followed to the edge.
    assert f.set_trajectory(request([(2.0, (2.0, 1.5, 3.0))]), now=0.0).accepted
    assert f.sample(2.0).positions == pytest.approx([2.0, 1.5, 3.0])


def test_acceleration_limits_must_be_positive():
    with pytest.raises(ValueError, match='acceleration limits must be > 0'):
        JointLimits(np.zeros(2), np.ones(2), np.ones(2), np.ones(2), np.array([1.0, 0.0]))
    assert list(LIMITS.acceleration) == [math.inf] * 3


def test_the_screen_of_all_points_agrees_with_checking_them_one_by_one():
    """validate() screens the points together (a 10,000-point trajectory took 0.9 s point by
    point) and explains the first it finds: over random trajectories, broken in random ways,
    it must find exactly what checking every point in order finds."""
    from controllers.joint_trajectory import _PointCheck
    rng = np.random.default_rng(7)
    outcomes = set()
    for trial in range(600):
        count = int(rng.integers(1, 7))
        times = np.cumsum(rng.uniform(0.05, 1.5, count)) - (0.5 if rng.random() < 0.2 else 0)
        q = rng.uniform(-1.0, 1.0, (count, 3)) * rng.uniform(0.1, 1.8)
        v = rng.uniform(-1.2, 1.2, (count, 3)) if rng.random() < 0.5 else None
        a = rng.uniform(-7, 7, (count, 3)) if v is not None and rng.random() < 0.5 else None
        fault = rng.integers(0, 6)
        k = int(rng.integers(0, count))
        if fault == 1:
            q[k, rng.integers(0, 3)] = math.nan
        elif fault == 2 and count > 1:
            times[k] = times[k - 1] if k else -0.1
        elif fault == 3:
            q[k, 1] = 1.7
        points = [(float(times[i]), tuple(q[i]), () if v is None else tuple(v[i]),
                   () if a is None else tuple(a[i])) for i in range(count)]
        start = None if rng.random() < 0.6 else float(rng.uniform(9.0, 11.0))
        req = request(points, start=start)
        f = TrajectoryFollower(NAMES, ACCEL, tuple(rng.uniform(-0.2, 0.2, 3)))
        check = _PointCheck(f, req, 10.0, None)
        one_by_one = check.explain(0)
        first = check.screen()
        assert (first is None) == (one_by_one == ''), (trial, one_by_one)
        if first is not None:
            assert check.explain(first) == one_by_one
        outcomes.add(one_by_one.split(':')[-1].split(' ')[1] if one_by_one else 'ok')
    assert len(outcomes) >= 6          # accepted, and several kinds of rejection


def test_a_long_trajectory_is_validated_and_interpolated_at_array_speed():
    """Issue 15, finding 7: a 10,000-point trajectory stopped the simulator's clock for
    0.6 s. It is now checked and interpolated together (tens of milliseconds; not timed
    here), sampled by bisection, and follows its waypoints exactly."""
    count = 10000
    t = 0.01 * np.arange(1, count + 1)
    q = 0.3 * np.sin(np.outer(t, [1.0, 0.5, 0.25]))
    f = follower()
    assert f.set_trajectory(request([(t[i], tuple(q[i])) for i in range(count)]), 0.0).accepted
    for i in (0, 1234, 5000, count - 1):
        assert f.sample(t[i]).positions == pytest.approx(q[i], abs=1e-12)
    bad = [(t[i], tuple(q[i])) for i in range(count)]
    bad[9000] = (t[9000], (0.0, 1.6, 0.0))
    result = follower().set_trajectory(request(bad), 0.0)
    assert result.reason == ('point 9000: j2 target 1.6000 is outside its limits '
                             '[-1.0000, 1.5000]')
