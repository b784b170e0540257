"""The youBot in the simulated world (no ROS): Mecanum base fidelity through contact physics,
command safety, and the arm and gripper following trajectories."""
import math

import numpy as np
import pytest

from controllers.base_fidelity import tracking_errors
from controllers.diff_drive import Pose2D
from controllers.joint_trajectory import TrajectoryPoint, TrajectoryRequest
from controllers.mecanum import MecanumGeometry, wheel_speeds
from controllers.transforms import yaw_from_quaternion
from controllers.youbot_arm import JOINT_NAMES
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from world_description import YOUBOT_WORLD
from world_description.resources import resolve_resource
from world_description.world_config import load_world

HZ = 240
K = 0.386


class Sink(NullSink):
    def __init__(self):
        self.timeouts = []

    def on_command_timeout(self, robot):
        self.timeouts.append(robot)


@pytest.fixture(scope='module')
def sim():
    world = SimWorld(load_world(resolve_resource(YOUBOT_WORLD)))
    runner = SimRunner(world, DriveLimits(cmd_vel_timeout=0.5), 100.0)
    yield world, runner
    world.close()


@pytest.fixture
def youbot(sim):
    world, runner = sim
    runner.reset()
    runner.advance(HZ // 2, Sink())          # settle on the wheels
    return world.robots['youbot'], runner


def _pose(robot):
    s = robot.sensors.base_state()
    return Pose2D(s.position[0], s.position[1], yaw_from_quaternion(s.orientation))


def _drive(robot, runner, command, seconds):
    """Hold a command (re-sent at 10 Hz like a teleop); return the mean measured twist after
    the first 0.5 s (the start-up)."""
    twists = []
    for k in range(int(seconds * HZ)):
        if k % (HZ // 10) == 0:
            runner.command('youbot', *command)
        runner.advance(1, Sink())
        if k >= int(0.5 * HZ) or seconds <= 0.5:
            s = robot.sensors.base_state()
            twists.append((s.linear[0], s.linear[1], s.angular[2]))
    return tuple(np.mean(twists, axis=0))


@pytest.mark.parametrize('command', [(0.2, 0.0, 0.0), (0.0, 0.2, 0.0), (0.0, 0.0, 0.5),
                                     (0.15, -0.1, 0.3)],
                         ids=['vx', 'vy', 'wz', 'combined'])
def test_odometry_follows_the_commanded_twist(youbot, command):
    robot, runner = youbot
    _drive(robot, runner, command, 0.5)     # up to speed (the command ramps at 1 m/s^2)
    start = _pose(robot)
    measured = _drive(robot, runner, command, 2.0)
    e = tracking_errors(command, 2.0, start, _pose(robot), measured, K)
    assert e.twist_error < 0.03
    assert e.position_error < 0.03
    assert e.yaw_error < 0.03
    assert e.cross_drift < 0.02


def test_wheel_joint_states_show_the_kinematic_wheel_speeds(youbot):
    robot, runner = youbot
    command = (0.15, -0.1, 0.3)
    _drive(robot, runner, command, 1.0)
    js = robot.sensors.joint_states()
    names = ['wheel_joint_fl', 'wheel_joint_fr', 'wheel_joint_rr', 'wheel_joint_rl']
    speeds = [js.velocities[js.names.index(n)] for n in names]
    expected = wheel_speeds(*command, MecanumGeometry(0.0475, K))
    assert speeds == pytest.approx(expected, rel=0.01)
    # Positions integrate the same speeds (the reported angle is sqrt(2) x the sphere's).
    before = [js.positions[js.names.index(n)] for n in names]
    _drive(robot, runner, command, 0.5)
    js = robot.sensors.joint_states()
    after = [js.positions[js.names.index(n)] for n in names]
    assert np.subtract(after, before) == pytest.approx(np.multiply(expected, 0.5), rel=0.02)


def test_commands_are_clamped_to_the_youbots_own_limits(youbot):
    robot, runner = youbot
    result = runner.command('youbot', 0.3, -3.0, 0.2)
    assert result.clamped and result.command == (0.3, -0.8, 0.2) and not result.wheel_limited
    assert runner.guards['youbot'].limits == (0.8, 0.8, 1.5)


def test_a_command_its_wheels_cannot_follow_is_slowed_along_the_same_path(youbot):
    # (0.8, -0.8, 1.5), each within its limit, asks a wheel for 45.9 rad/s (URDF: 30): the
    # drive takes the same twist scaled until its fastest wheel is at its limit.
    robot, runner = youbot
    result = runner.command('youbot', 2.0, -3.0, 4.0)
    assert result.clamped and result.wheel_limited
    assert np.divide(result.command, (0.8, -0.8, 1.5)) == pytest.approx([30 / 45.89] * 3,
                                                                        rel=1e-3)
    speeds = wheel_speeds(*result.command, MecanumGeometry(0.0475, K))
    assert max(abs(w) for w in speeds) == pytest.approx(30.0, rel=1e-9)
    assert max(abs(w) for w in speeds) <= 30.0


def test_a_step_to_full_speed_is_taken_at_the_acceleration_limits(youbot):
    # A command jumping from rest to full speed (a controller catching up after a stall)
    # reaches the wheels at 1 m/s^2 and 2 rad/s^2. Unlimited, the base accelerates at 6 m/s^2
    # here; in the cell it reached 0.75 m/s in 0.2 s and flung the raised arm (arm_joint_4 at
    # 1.8x its speed limit).
    robot, runner = youbot
    arm = robot.controllers['arm_controller']

    class Applied(Sink):
        def __init__(self):
            super().__init__()
            self.commands = []

        def on_command_applied(self, name, t, command):
            assert command == runner.applied(name)
            self.commands.append((t, command))

    sink, speeds, worst_joint = Applied(), [], 0.0
    t0 = runner.world.sim_time_ns
    for k in range(int(1.2 * HZ)):
        if k % (HZ // 10) == 0:
            runner.command('youbot', 0.8, 0.0, 1.5)
        runner.advance(1, sink)
        s = robot.sensors.base_state()
        speeds.append(np.hypot(*s.linear[:2]))
        worst_joint = max(worst_joint, float(np.abs(arm.actual()[1]).max()))
    dt = runner.world.time_step
    times = (np.array([t for t, _ in sink.commands]) - t0) * 1e-9
    commands = np.array([c for _, c in sink.commands])
    assert commands[-1] == pytest.approx((0.8, 0.0, 1.5))
    assert times[-1] == pytest.approx(0.8, abs=2 * dt)        # vx's ramp: 0.8 s at 1 m/s^2
    rates = np.abs(np.diff(commands, axis=0)) / np.diff(times)[:, None]
    assert rates[:, 0].max() <= 1.0 + 1e-6 and rates[:, 2].max() <= 2.0 + 1e-6
    # The base follows the ramp (its motors are far stronger than the ramp needs).
    accel = np.diff(speeds) / dt
    assert np.convolve(accel, np.ones(12) / 12, 'valid').max() < 1.3
    assert worst_joint <= math.pi / 2


def test_nan_stops_the_base_and_a_stale_command_times_out(youbot):
    robot, runner = youbot
    _drive(robot, runner, (0.2, 0.1, 0.0), 1.0)
    result = runner.command('youbot', math.nan, 0.0, 0.0)
    assert not result.accepted and 'non-finite' in result.reason
    runner.advance(HZ, Sink())
    assert np.abs(robot.sensors.base_state().linear[:2]).max() < 0.005
    runner.command('youbot', 0.0, 0.2, 0.0)
    sink = Sink()
    runner.advance(int(0.8 * HZ), sink)     # timeout 0.5 s: stops, then coasts to rest
    assert sink.timeouts == ['youbot']
    assert robot.drive.targets == (0.0, 0.0, 0.0, 0.0)
    runner.advance(HZ // 2, Sink())
    assert abs(robot.sensors.base_state().linear[1]) < 0.005


def _run_until(runner, seconds):
    runner.advance(int(seconds * HZ), Sink())


def test_the_arm_follows_a_trajectory_to_its_goal(youbot):
    robot, runner = youbot
    arm = robot.controllers['arm_controller']
    goal = (1.0, 0.8, -1.2, 0.9, 1.5)
    request = TrajectoryRequest(JOINT_NAMES, (TrajectoryPoint(1.0, (0.5, 0.4, -0.6, 0.45, 0.7)),
                                              TrajectoryPoint(2.5, goal)))
    assert runner.set_trajectory('youbot', 'arm_controller', request).accepted
    worst = 0.0
    for _ in range(int(2.5 * HZ)):
        runner.advance(1, Sink())
        worst = max(worst, float(np.abs(arm.desired.positions - arm.actual()[0]).max()))
    _run_until(runner, 0.5)
    assert arm.actual()[0] == pytest.approx(goal, abs=1e-3)
    assert worst < 0.02                          # rad, while moving
    # Its velocity never exceeded the URDF limit (pi/2 rad/s).
    assert np.abs(arm.actual()[1]).max() <= math.pi / 2 + 1e-6


def test_a_rejected_trajectory_leaves_the_arm_holding(youbot):
    robot, runner = youbot
    arm = robot.controllers['arm_controller']
    held = arm.actual()[0]
    bad = TrajectoryRequest(JOINT_NAMES, (TrajectoryPoint(1.0, (0.0, 3.0, 0.0, 0.0, 0.0)),))
    result = runner.set_trajectory('youbot', 'arm_controller', bad)
    assert not result.accepted and 'arm_joint_2 target 3.0000 is outside' in result.reason
    _run_until(runner, 1.0)
    assert arm.actual()[0] == pytest.approx(held, abs=1e-3)


def test_the_gripper_closes_and_opens(youbot):
    robot, runner = youbot
    gripper = robot.controllers['gripper_controller']
    assert gripper.actual()[0] == pytest.approx((0.0115, 0.0115), abs=1e-4)   # starts open
    close = TrajectoryRequest(gripper.joint_names, (TrajectoryPoint(1.0, (0.0, 0.0)),))
    assert runner.set_trajectory('youbot', 'gripper_controller', close).accepted
    _run_until(runner, 1.5)
    assert gripper.actual()[0] == pytest.approx((0.0, 0.0), abs=2e-4)
    too_fast = TrajectoryRequest(gripper.joint_names, (TrajectoryPoint(0.1, (0.0115, 0.0115)),))
    assert 'above its velocity limit' in runner.set_trajectory(
        'youbot', 'gripper_controller', too_fast).reason


def test_reset_returns_the_arm_to_its_start(youbot):
    robot, runner = youbot
    arm = robot.controllers['arm_controller']
    runner.set_trajectory('youbot', 'arm_controller', TrajectoryRequest(
        JOINT_NAMES, (TrajectoryPoint(1.0, (0.5, 0.3, 0.2, 0.1, 0.0)),)))
    _run_until(runner, 1.2)
    runner.reset()
    _run_until(runner, 0.5)
    assert arm.actual()[0] == pytest.approx(np.zeros(5), abs=2e-3)
    assert not arm.follower.active


def test_an_arm_pushed_against_the_floor_is_reported_with_what_it_touches(youbot):
    """A target below the floor: the arm stops on it, off its reference (as arm_joint_4 at
    0.86 rad against a held 0.72), and the hold watch names the contact; back in free space it
    reports the arm at its reference again. A free pose is never reported."""
    from sim_bridge.hold_watch import HoldWatch
    robot, runner = youbot
    world = runner.world
    watch = HoldWatch(world)
    reports = []

    def move(goal, seconds):
        # (No path tolerance, which would stop the arm at the floor: see the next test.)
        request = TrajectoryRequest(JOINT_NAMES, (TrajectoryPoint(seconds, goal),))
        assert runner.set_trajectory('youbot', 'arm_controller', request,
                                     path_tolerance=[0.0] * 5).accepted
        for _ in range(int((seconds + 1.5) * HZ)):
            runner.advance(1, Sink())
            reports.extend(watch.update(world.sim_time))

    move((0.0, 0.5, 0.5, 0.72, 0.0), 2.0)                     # free: held at the reference
    assert reports == []
    move((0.0, 1.5, 1.65, 0.72, 0.0), 3.0)                    # the fingers reach the floor
    blocked, = reports
    assert blocked.blocked and blocked.group == 'youbot/arm_controller'
    assert 'arm_joint_4' in blocked.text or 'arm_joint_3' in blocked.text
    assert 'gripper_finger_link' in blocked.text and 'on the floor' in blocked.text
    move((0.0, 0.0, 0.0, 0.0, 0.0), 3.0)
    assert [r.blocked for r in reports] == [True, False]
    assert reports[-1].text == 'youbot/arm_controller is back at its reference'


def test_a_trajectory_the_arm_cannot_follow_is_aborted_and_the_arm_holds(youbot):
    """JTC's path tolerance (the world file's 0.25 rad): the arm driven into the floor lags
    its reference; the trajectory is aborted, naming the joint and the contacts, and the arm
    holds where it stopped (the reference is its position then), so no hold is reported."""
    from sim_bridge.hold_watch import HoldWatch
    robot, runner = youbot
    arm = robot.controllers['arm_controller']
    assert list(arm.path_tolerance) == [0.25] * 5
    watch = HoldWatch(runner.world)
    aborted, reports = [], []

    class Aborts(Sink):
        def on_trajectory_aborted(self, robot, controller, reason):
            aborted.append((robot, controller, reason, runner.world.sim_time))

    request = TrajectoryRequest(JOINT_NAMES, (TrajectoryPoint(3.0, (0.0, 1.5, 1.65, 0.72, 0.0)),))
    start = runner.world.sim_time
    assert runner.set_trajectory('youbot', 'arm_controller', request).accepted
    for _ in range(int(4.5 * HZ)):
        runner.advance(1, Aborts())
        reports.extend(watch.update(runner.world.sim_time))
    (who, controller, reason, when), = aborted
    assert (who, controller) == ('youbot', 'arm_controller') and when - start < 3.0
    assert 'path tolerance violated' in reason and 'on the floor' in reason
    assert not arm.follower.active
    assert np.abs(arm.desired.positions - arm.actual()[0]).max() < 0.05
    assert reports == []


def test_a_non_finite_physics_state_stops_the_robot_and_reset_restores_it():
    """Issue 15, finding 1: once PyBullet carried a NaN (from NaN motor targets), resetting
    the state left the body dead: the base sank through the floor and no trajectory moved the
    arm. The runner finds the NaN at the next state check, loads the body again at its start
    pose, refuses commands until reset, and after reset the robot drives and the arm moves."""
    import pybullet
    world = SimWorld(load_world(resolve_resource(YOUBOT_WORLD)))
    runner = SimRunner(world, DriveLimits(max_speed=0.5, cmd_vel_timeout=0.5), 100.0)
    robot = world.robots['youbot']
    arm = robot.controllers['arm_controller']
    faults = []

    class Faults(Sink):
        def on_fault(self, name, reason):
            faults.append((name, reason))

    try:
        runner.advance(HZ // 2, Faults())
        for joint in arm.joints:            # what the overflowing interpolation sent
            robot.client.setJointMotorControl2(robot.body, joint, pybullet.POSITION_CONTROL,
                                               targetPosition=math.nan, force=10.0)
        world.step()
        assert robot.state_problem()
        runner.advance(HZ // 50, Faults())           # to the next state check (100 Hz)
        (name, reason), = faults
        assert name == 'youbot' and 'not finite' in reason and 'the floor' in reason
        assert not robot.state_problem()
        assert robot.sensors.base_state().position == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)
        refused = runner.command('youbot', 0.3, 0.0, 0.0)
        assert not refused.accepted and 'reset the simulator' in refused.reason
        move = TrajectoryRequest(JOINT_NAMES, (TrajectoryPoint(1.0, (0.5, 0.3, 0.2, 0.1, 0.0)),))
        assert 'reset the simulator' in runner.set_trajectory('youbot', 'arm_controller',
                                                              move).reason
        runner.reset()
        assert runner.faults == {}
        for _ in range(10):                                  # 1 s at 0.3 m/s
            assert runner.command('youbot', 0.3, 0.0, 0.0).accepted
            runner.advance(HZ // 10, Faults())
        assert robot.sensors.base_state().position[0] > 0.2
        assert runner.set_trajectory('youbot', 'arm_controller', move).accepted
        runner.advance(int(1.5 * HZ), Faults())
        arm = robot.controllers['arm_controller']            # (a new group after the reload)
        assert arm.actual()[0] == pytest.approx((0.5, 0.3, 0.2, 0.1, 0.0), abs=0.01)
        assert len(faults) == 1
    finally:
        world.close()


def test_reset_reloads_a_body_whose_state_is_not_finite():
    import pybullet
    world = SimWorld(load_world(resolve_resource(YOUBOT_WORLD)))
    runner = SimRunner(world, DriveLimits(max_speed=0.5), 100.0)
    robot = world.robots['youbot']
    try:
        for joint in robot.controllers['arm_controller'].joints:
            robot.client.setJointMotorControl2(robot.body, joint, pybullet.POSITION_CONTROL,
                                               targetPosition=math.nan, force=10.0)
        world.step()
        assert robot.state_problem()
        runner.reset()                  # before any state check saw it
        assert not robot.state_problem()
        for _ in range(10):
            runner.command('youbot', 0.3, 0.0, 0.0)
            runner.advance(HZ // 10, Sink())
        assert robot.sensors.base_state().position[0] > 0.2
    finally:
        world.close()
