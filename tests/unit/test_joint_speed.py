"""Joints never faster than their limits (issue 48): the brake at each joint's speed limit
(sim_bridge.joint_speed), the book of what it did, and what a trial's result keeps of it."""
import math
from types import SimpleNamespace

import numpy as np
import pybullet
import pytest

from cell_layout.joint_speeds import driven_past, speed_limits
from sim_bridge.joint_speed import DRIVEN_PAST, BrakeBook, Braked
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from trial_record.records import RecordError
from trial_record.result import TrialResult
from world_description import PIPELINE_CELL, YOUBOT_WORLD
from world_description.resources import resolve_resource
from world_description.world_config import load_world

ARM = [f'arm_joint_{i}' for i in range(1, 6)]


class Brakes(NullSink):
    def __init__(self):
        self.braked = []

    def on_joints_braked(self, robot, time_ns, braked):
        self.braked += [(robot, time_ns, b) for b in braked]


def _ratios(robot):
    """Each limited joint's speed over its URDF limit, as its joint states report it."""
    states = robot.sensors.joint_states()
    limits = [robot.joint_limits(n)[2] for n in states.names]
    return {n: abs(v) / lim for n, v, lim in zip(states.names, states.velocities, limits)
            if lim > 0.0}


@pytest.fixture
def youbot():
    world = SimWorld(load_world(resolve_resource(YOUBOT_WORLD)))
    yield world, SimRunner(world, DriveLimits(), 100.0)
    world.close()


def test_a_joint_the_world_flings_past_its_limit_is_braked_back_to_it_in_the_same_step(youbot):
    world, runner = youbot
    robot = world.robots['youbot']
    j = robot.joint_index['arm_joint_2']
    world.client.resetJointState(robot.body, j, 0.3, -3.0 * math.pi / 2)   # (3 times its limit)
    sink = Brakes()
    runner.advance(1, sink)
    ratios = _ratios(robot)
    assert max(ratios.values()) <= 1.0
    assert ratios['arm_joint_2'] == pytest.approx(1.0)
    [(name, t_ns, b)] = [x for x in sink.braked if x[2].joint == 'arm_joint_2']
    assert name == 'youbot' and t_ns == world.sim_time_ns
    assert b.ratio > 2.5 and b.speed < 0.0 and b.limit == pytest.approx(math.pi / 2)
    assert b.torque > 9.5 and not b.torque_is_force     # (more than its motor could do)


def test_an_arm_that_cannot_hold_itself_sags_no_faster_than_its_joints_may_turn(youbot):
    # Its motors at a hundredth of their torque: gravity takes the arm down from leaning out,
    # as far as the physics says, and every joint turns at its limit at most all the way.
    world, runner = youbot
    robot = world.robots['youbot']
    for name, q in zip(ARM[1:3], (1.2, -0.3)):          # leaning out, forward
        world.client.resetJointState(robot.body, robot.joint_index[name], q, 0.0)
    group = robot.controllers['arm_controller']
    group.hold_current()
    group._effort = [e / 100.0 for e in group._effort]
    group._motor_targets = None
    sink = Brakes()
    before = robot.sensors.joint_positions(ARM)
    worst = 0.0
    for _ in range(480):
        runner.advance(1, sink)
        worst = max(worst, max(_ratios(robot).values()))
    assert worst <= 1.0
    assert np.abs(robot.sensors.joint_positions(ARM) - before).max() > 0.5       # it sagged
    fast = [b for _, _, b in sink.braked if b.ratio > 1.0 + DRIVEN_PAST]
    assert fast and {b.joint for b in fast} <= set(ARM)


def test_the_brake_changes_the_braked_joint_alone_and_says_what_impulse_it_took():
    # The Zu 12 (a fixed base: its mass matrix is the whole body's) moving every joint, its
    # shoulder at twice its limit: the shoulder is brought to its limit, the other joints (geared
    # as well) keep their speeds, and the brake torque is the shoulder's share of M dv.
    world = SimWorld(load_world(resolve_resource(PIPELINE_CELL)))
    try:
        robot = world.robots['zu12']
        p = world.client
        rng = np.random.default_rng(48)
        for j in robot.movable:
            p.resetJointState(robot.body, j, float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)))
        fast = robot.joint_index['joint_2']
        p.resetJointState(robot.body, fast, 0.5, 4.0)                   # (limit 2.094)
        before = np.array([s[1] for s in p.getJointStates(robot.body, robot.movable)])
        braked = robot.speed_limiter.enforce()
        after = np.array([s[1] for s in p.getJointStates(robot.body, robot.movable)])
        q = [s[0] for s in p.getJointStates(robot.body, robot.movable)]
        impulse = np.asarray(p.calculateMassMatrix(robot.body, q)) @ (after - before)
        k = robot.movable.index(fast)
        assert [b.joint for b in braked] == ['joint_2']
        assert after[k] == pytest.approx(math.radians(120.0), abs=1e-12)
        assert np.delete(after, k) == pytest.approx(np.delete(before, k), abs=0.0)
        assert braked[0].torque == pytest.approx(abs(impulse[k]) / world.time_step)
        assert braked[0].torque > 330.0            # (the motor's torque could not have done it)
        assert robot.speed_limiter.enforce() == []
    finally:
        world.close()


def test_a_wheel_of_the_youbot_is_held_to_its_limit_too(youbot):
    world, runner = youbot
    robot = world.robots['youbot']
    j = robot.joint_index['wheel_joint_fl']
    world.client.resetJointState(robot.body, j, 0.0, 100.0)
    runner.advance(1, NullSink())
    assert _ratios(robot)['wheel_joint_fl'] == pytest.approx(1.0)
    assert max(_ratios(robot).values()) <= 1.0


def test_the_book_names_a_joint_driven_past_its_limit_and_keeps_its_worst():
    book = BrakeBook()
    slop = Braked('gripper_finger_joint_l', 0.0201, 0.02, 0.001, True, 10.0)
    nudged = Braked('gripper_finger_joint_r', 0.2, 0.02, 0.5, True, 10.0)
    assert book.add('youbot', 1.0, [slop, nudged]) == []      # (within what its motor gives)
    lines = book.add('youbot', 2.5, [Braked('arm_joint_4', -2.2, math.pi / 2, 3.25, False, 2.0)])
    assert lines == ['youbot: arm_joint_4 was driven past its speed limit at 2.500 s: 2.2 '
                     '(1.401 times its 1.571); braked back to it with 3.25 N m (its motor: 2)']
    book.add('youbot', 3.0, [Braked('arm_joint_4', 1.8, math.pi / 2, 2.5, False, 2.0)])
    driven, message, values = book.status('youbot')
    values = dict(values)
    assert driven and 'arm_joint_4, 1.401 times its limit at 2.50 s' in message
    assert values['arm_joint_4/count'] == '2' and values['arm_joint_4/time'] == '2.5000'
    assert values['brakings'] == '4'
    assert book.status('zu12')[0] is False
    book.clear()
    assert book.status('youbot')[0] is False


def test_a_result_keeps_what_the_simulator_said_and_reads_it_back_checked():
    status = SimpleNamespace(hardware_id='youbot', values=[
        SimpleNamespace(key=k, value=v) for k, v in [
            ('brakings', '7'), ('arm_joint_4/ratio', '1.2'), ('arm_joint_4/speed', '1.885'),
            ('arm_joint_4/limit', '1.5708'), ('arm_joint_4/brake', '2.4'),
            ('arm_joint_4/time', '12.5'), ('arm_joint_4/count', '3'),
            ('arm_joint_2/ratio', 'nan'), ('arm_joint_2/speed', '1'), ('arm_joint_2/limit', '1'),
            ('arm_joint_2/brake', '1'), ('arm_joint_2/time', '1'), ('arm_joint_2/count', '1')]])
    driven = driven_past(SimpleNamespace(status=[status]))
    assert driven == [{'robot': 'youbot', 'joint': 'arm_joint_4', 'ratio': 1.2, 'speed': 1.885,
                       'limit': 1.5708, 'brake': 2.4, 'time': 12.5, 'count': 3}]
    result = TrialResult(status='completed', joints_driven_past=driven)
    assert TrialResult.from_dict(result.to_dict()).joints_driven_past == driven
    bad = result.to_dict()
    bad['joints_driven_past'][0]['ratio'] = -1.0
    with pytest.raises(RecordError, match='ratio'):
        TrialResult.from_dict(bad)


def test_every_limited_joint_of_a_robot_is_watched_not_only_its_arm():
    world = load_world(resolve_resource(PIPELINE_CELL))
    youbot = speed_limits(world, 'youbot')
    assert youbot['gripper_finger_joint_l'] == 0.02 and youbot['wheel_joint_fl'] == 30.0
    assert all(youbot[j] == pytest.approx(math.pi / 2) for j in ARM)
    assert list(speed_limits(world, 'zu12')) == [f'joint_{i}' for i in range(1, 7)]
    assert speed_limits(world, 'nobody') == {}
    assert pybullet.isNumpyEnabled() in (0, 1)
