"""A FollowJointTrajectory goal judged as JTC judges it (controllers.trajectory_goal)."""
import math

from controllers.trajectory_goal import (
    GOAL_TOLERANCE_VIOLATED,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    GoalMonitor,
    Tolerance,
    check_tolerances,
)

J = ('a', 'b')
Z = (0.0, 0.0)


def test_no_tolerances_succeed_when_the_trajectory_ends():
    m = GoalMonitor(J, end_time=2.0)
    assert m.check(1.0, (1.0, 1.0), Z, (0.0, 0.0), Z) is None      # far off: not checked
    assert m.check(2.0, (1.0, 1.0), Z, (0.5, 0.5), Z).code == SUCCESSFUL


def test_a_path_tolerance_is_checked_until_the_end():
    m = GoalMonitor(J, end_time=2.0, path=[('b', Tolerance(position=0.1))])
    assert m.check(0.5, (1.0, 1.0), Z, (0.0, 0.95), Z) is None     # 'a' is not checked
    out = m.check(0.6, (1.0, 1.0), Z, (0.0, 0.85), Z)
    assert out.code == PATH_TOLERANCE_VIOLATED and 'b is 0.1500' in out.message
    assert m.check(0.6, (1.0, 1.0), Z, (0.0, math.nan), Z).code == PATH_TOLERANCE_VIOLATED


def test_a_velocity_tolerance_too():
    m = GoalMonitor(J, end_time=2.0, path=[('a', Tolerance(velocity=0.2))])
    assert m.check(1.0, Z, (1.0, 0.0), Z, (0.9, 5.0)) is None
    assert m.check(1.0, Z, (1.0, 0.0), Z, (0.7, 0.0)).code == PATH_TOLERANCE_VIOLATED


def test_the_goal_tolerance_waits_goal_time_tolerance_then_fails():
    m = GoalMonitor(J, end_time=2.0, goal=[('a', Tolerance(position=0.01))],
                    goal_time_tolerance=0.5)
    assert m.check(2.2, (1.0, 0.0), Z, (0.9, 0.0), Z) is None      # late, still allowed
    assert m.check(2.3, (1.0, 0.0), Z, (0.995, 0.0), Z).code == SUCCESSFUL
    out = m.check(2.6, (1.0, 0.0), Z, (0.9, 0.0), Z)
    assert out.code == GOAL_TOLERANCE_VIOLATED and 'goal_time_tolerance 0.500' in out.message


def test_without_goal_time_tolerance_the_goal_waits_as_jtc():
    m = GoalMonitor(J, end_time=2.0, goal=[('a', Tolerance(position=0.01))])
    assert m.check(100.0, (1.0, 0.0), Z, (0.9, 0.0), Z) is None


def test_bad_tolerances_are_named():
    assert check_tolerances(J, [('a', Tolerance(0.1, 0.2, 0.3))]) == ''
    assert check_tolerances(J, [('a', Tolerance(position=-1.0))]) == ''      # erase
    assert 'not a joint' in check_tolerances(J, [('c', Tolerance())])
    assert 'finite' in check_tolerances(J, [('a', Tolerance(velocity=math.inf))])
    assert 'finite' in check_tolerances(J, [('b', Tolerance(position=-0.5))])
