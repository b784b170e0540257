"""The youBot over DDS: the base under cmd_vel in real time, arm trajectories (good and
malformed). test_youbot_base_graph.py has the base's fidelity (lock-step), and
test_kinematics_graph.py the kinematics node moving the arm to an IK target."""
import math
import time

import numpy as np
import pytest
from control_msgs.msg import JointTrajectoryControllerState
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from controllers.diff_drive import Pose2D
from controllers.transforms import yaw_from_quaternion
from controllers.youbot_arm import JOINT_NAMES
from helpers import (
    NodeProcess,
    latest_stamp,
    moving,
    stamp_s,
    wait_for,
    wait_for_stamp,
)

WORLD = 'world:=package://world_description/worlds/youbot.yaml'
RTF = 2.0


@pytest.fixture(scope='module')
def youbot_sim(tmp_path_factory):
    proc = NodeProcess('sim_node', ['-p', WORLD, '-p', f'real_time_factor:={RTF}'],
                       tmp_path_factory.mktemp('youbot'))
    yield proc
    proc.stop()


class Base:
    def __init__(self, probe):
        self.probe = probe
        self.clock = probe.collect(Clock, '/clock')
        self.odom = probe.collect(Odometry, '/youbot/odom')
        self.pub = probe.node.create_publisher(Twist, '/youbot/cmd_vel', 10)
        wait_for(lambda: self.clock and self.odom and self.pub.get_subscription_count() > 0,
                 20.0, what='youbot topics')

    def now(self):
        return stamp_s(self.clock[-1][1].clock)

    def send(self, vx, vy, wz):
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, wz
        self.pub.publish(msg)

    def hold(self, command, seconds):
        """Send ``command`` for ``seconds`` of simulated time (at 20 Hz of it), then a stop;
        returns once the odometry of the hold's end is in (on a loaded machine it comes
        later than the clock)."""
        end = self.now() + seconds
        while self.now() < end:
            self.send(*command)
            time.sleep(0.05 / RTF)          # (the sender's rate, not a wait)
        self.send(0.0, 0.0, 0.0)
        wait_for_stamp(self.odom, end, what='the odometry of the end of the hold')


def _pose2d(msg):
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    return Pose2D(p.x, p.y, yaw_from_quaternion((o.x, o.y, o.z, o.w)))


def _trajectory(positions, seconds, names=JOINT_NAMES):
    point = JointTrajectoryPoint(positions=[float(p) for p in positions])
    point.time_from_start.sec = int(seconds)
    point.time_from_start.nanosec = int(round((seconds - int(seconds)) * 1e9))
    return JointTrajectory(joint_names=list(names), points=[point])


def _arm_positions(joint_states):
    msg = joint_states[-1][1]
    return np.array([msg.position[msg.name.index(n)] for n in JOINT_NAMES])


def test_arm_trajectory_reaches_its_goal_and_malformed_ones_are_rejected(youbot_sim, probe):
    assert probe.call(Trigger, '/sim_node/reset', Trigger.Request()).success
    joints = probe.collect(JointState, '/youbot/joint_states')
    states = probe.collect(JointTrajectoryControllerState,
                           '/youbot/arm_controller/controller_state')
    pub = probe.node.create_publisher(JointTrajectory, '/youbot/arm_controller/joint_trajectory',
                                      10)
    wait_for(lambda: joints and states and pub.get_subscription_count() > 0, 20.0,
             what='arm topics')
    goal = (0.8, 0.6, 0.9, -0.5, 1.2)
    pub.publish(_trajectory(goal, 2.0))
    wait_for(lambda: moving(states[-1][1]), 10.0, what='the trajectory to start')
    wait_for(lambda: not moving(states[-1][1]), 20.0, what='the trajectory to end')
    wait_for(lambda: _arm_positions(joints) == pytest.approx(goal, abs=2e-3), 10.0,
             what='the arm at its goal')
    tracked = [m for _, m in list(states) if moving(m)]
    worst = max(max(abs(e) for e in m.error.positions) for m in tracked)
    assert worst < 0.02                               # rad while moving
    assert list(tracked[0].joint_names) == list(JOINT_NAMES)
    # Malformed: the arm holds, the node lives on and logs each reason.
    bad = [_trajectory(goal, 1.0, names=('arm_joint_1', 'elbow', 'arm_joint_3',
                                         'arm_joint_4', 'arm_joint_5')),
           _trajectory((math.nan, 0.0, 0.0, 0.0, 0.0), 1.0),
           _trajectory((0.0, 2.5, 0.0, 0.0, 0.0), 1.0),
           JointTrajectory(joint_names=list(JOINT_NAMES))]
    for msg in bad:
        pub.publish(msg)                               # (each reason its own log line)
    reasons = ("unknown joints ['elbow']", 'non-finite positions',
               'arm_joint_2 target 2.5000 is outside its limits', 'empty trajectory')
    wait_for(lambda: all(r in youbot_sim.output() for r in reasons), 10.0,
             what='every rejection logged')
    # A second of simulated time after the last rejection, the arm still holds its goal.
    wait_for_stamp(states, latest_stamp(states) + 1.0, what='1 s of simulated time')
    assert _arm_positions(joints) == pytest.approx(goal, abs=2e-3)
    assert youbot_sim.alive()
    # ... and still follows a good one afterwards.
    pub.publish(_trajectory(np.zeros(5), 2.0))
    wait_for(lambda: np.abs(_arm_positions(joints)).max() < 2e-3, 20.0, what='the arm home')


def test_teleop_drives_the_base_in_every_direction(youbot_sim, probe, tmp_path):
    """Holonomic teleop script on the youBot's cmd_vel, in simulated time: each leg moves the
    base the way its key says (half speed: 0.1 m/s or 0.1 rad/s, for 1 s each), as far as the
    commands the wheels took (``cmd_vel_out``) say. The script opens with a 1 s stop: a process
    starting up on two cores can starve the simulator, which then catches up in bursts."""
    assert probe.call(Trigger, '/sim_node/reset', Trigger.Request()).success
    odom = probe.collect(Odometry, '/youbot/odom')
    applied = probe.collect(TwistStamped, '/youbot/cmd_vel_out')
    wait_for(lambda: odom, 20.0, what='odometry')     # (the applied command: on each change)
    teleop = NodeProcess('teleop', ['-r', '__ns:=/youbot', '-p', 'holonomic:=true',
                                    '-p', 'use_sim_time:=true', '-p', 'publish_rate:=20.0',
                                    '-p', 'script:=stop 1s, forward 1s, stop 0.5s, '
                                          'strafe_left 1s, stop 0.5s, backward 1s, stop 0.5s, '
                                          'strafe_right 1s, stop 0.5s, left 1s, stop 0.5s, '
                                          'right 1s, stop'],
                         tmp_path)
    try:
        wait_for(lambda: not teleop.alive(), 60.0, what='the script to end')
    finally:
        teleop.stop()
    # The base at rest on the last stop: half a second of simulated time more of odometry.
    wait_for_stamp(odom, latest_stamp(odom) + 0.5, what='0.5 s of simulated time')
    # The legs, from the odometry afterwards: each run of motion between two rests, runs the
    # same way merged (paced at 2x, a teleop process starved for 0.25 s of wall time misses the
    # command timeout, and the base rightly stops until its next command). Each leg moves the
    # base the way its key says at the commanded speed (the median twist, in the base frame),
    # and as far as the commands the wheels took in that time: how long a leg lasts depends on
    # when the teleop process runs, which on a busy machine can be late.
    history = [m for _, m in list(odom)]
    commands = sorted((stamp_s(m.header.stamp), np.array(
        [m.twist.linear.x, m.twist.linear.y, m.twist.angular.z])) for _, m in list(applied))
    moving = [_moving(m) for m in history]
    legs, k = [], 1
    while k < len(history):
        if moving[k] and not moving[k - 1]:
            end = next((j for j in range(k, len(history)) if not moving[j]), len(history) - 1)
            twist = np.median([(m.twist.twist.linear.x, m.twist.twist.linear.y,
                                m.twist.twist.angular.z) for m in history[k:end]], axis=0)
            way = tuple(np.round(twist, 1))
            if legs and legs[-1][2] == way:
                legs[-1][1] = end
            else:
                legs.append([k - 1, end, way])
            k = end
        k += 1
    log = teleop.output()
    expected = [(0.1, 0, 0), (0, 0.1, 0), (-0.1, 0, 0), (0, -0.1, 0), (0, 0, 0.1), (0, 0, -0.1)]
    assert [way for _, _, way in legs] == [tuple(float(v) for v in w) for w in expected], (
        legs, log)
    for (first, last, _), want in zip(legs, expected):
        a, b = _pose2d(history[first]), _pose2d(history[last])
        moved = np.dot((b.x - a.x, b.y - a.y, b.yaw - a.yaw), want) / 0.1
        taken = np.dot(_integral(commands, stamp_s(history[first].header.stamp),
                                 stamp_s(history[last].header.stamp)), want) / 0.1
        assert 0.03 < taken < 0.15, (want, taken, log)       # some of the leg's second, no more
        assert moved == pytest.approx(taken, rel=0.15, abs=0.005), (want, moved, taken)


def _integral(commands, t0, t1):
    """The integral over [t0, t1] of the applied command (held from each stamp to the next)."""
    total = np.zeros(3)
    for (t, value), (t_next, _) in zip(commands, commands[1:] + [(math.inf, None)]):
        lo, hi = max(t, t0), min(t_next, t1)
        if hi > lo:
            total += value * (hi - lo)
    return total


def _moving(msg):
    t = msg.twist.twist
    return max(abs(t.linear.x), abs(t.linear.y), abs(t.angular.z)) > 0.01


def test_arm_tracking_can_be_analysed_from_a_bag(youbot_sim, probe, tmp_path):
    from recording.analysis import to_markdown, write_report
    topic = '/youbot/arm_controller/controller_state'
    rec = NodeProcess('recorder', ['-p', f'output_dir:={tmp_path}', '-p', 'bag_name:=arm',
                                   '-p', f'topics:=[{topic}, /youbot/odom]'], tmp_path)
    try:
        wait_for(lambda: 'recording /youbot/odom ' in rec.output(), 20.0, what='the recorder')
        states = probe.collect(JointTrajectoryControllerState, topic)
        pub = probe.node.create_publisher(JointTrajectory,
                                          '/youbot/arm_controller/joint_trajectory', 10)
        wait_for(lambda: states and pub.get_subscription_count() > 0, 20.0, what='the arm')
        pub.publish(_trajectory((-0.7, 0.4, 1.0, 0.6, -1.0), 1.5))
        wait_for(lambda: moving(states[-1][1]), 10.0, what='the trajectory to start')
        wait_for(lambda: not moving(states[-1][1]), 20.0, what='the trajectory to end')
        pub.publish(_trajectory(np.zeros(5), 1.5))
        wait_for(lambda: moving(states[-1][1]), 10.0, what='the way back to start')
        wait_for(lambda: not moving(states[-1][1]), 20.0, what='the way back to end')
    finally:
        assert rec.stop() == 0
    report = write_report(tmp_path / 'arm', tmp_path / 'report')
    rows = {t.joint: t for t in report.tracking if t.topic == topic}
    assert sorted(rows) == list(JOINT_NAMES)
    for row in rows.values():
        assert row.samples >= 300                      # 100 Hz over more than 3 s
        assert 0.0 < row.max_abs_error < 0.02 and row.rms_error < row.max_abs_error
    assert '## Joint tracking' in to_markdown(report)


def test_arm_move_sends_a_trajectory_and_reports_the_result(youbot_sim, tmp_path):
    ok = NodeProcess('arm_move', ['-r', '__ns:=/youbot', '-p',
                                  'positions:=[0.3, 0.4, 0.5, 0.6, 0.7]', '-p', 'duration:=1.5'],
                     tmp_path, name='arm_move_ok')
    wait_for(lambda: not ok.alive(), 60.0, what='arm_move to finish')
    assert ok.stop() == 0 and 'reached the target' in ok.output()
    bad = NodeProcess('arm_move', ['-r', '__ns:=/youbot', '-p',
                                   'positions:=[0.3, 2.4, 0.5, 0.6, 0.7]'],
                      tmp_path, name='arm_move_bad')
    wait_for(lambda: not bad.alive(), 60.0, what='arm_move to give up')
    assert bad.stop() == 1 and 'did not start the trajectory' in bad.output()
    assert 'arm_joint_2 target 2.4000 is outside' in youbot_sim.output()
    home = NodeProcess('arm_move', ['-r', '__ns:=/youbot', '-p', 'duration:=1.5'], tmp_path,
                       name='arm_move_home')
    wait_for(lambda: not home.alive(), 60.0, what='arm_move home')
    assert home.stop() == 0


def test_a_nan_in_any_twist_field_stops_the_base(youbot_sim, probe):
    """Issue 15, finding 8: angular.x NaN beside a valid linear.x was ignored, and the youBot
    drove on at full speed. A non-finite value in any field means the sender is broken."""
    base = Base(probe)
    applied = probe.collect(TwistStamped, '/youbot/cmd_vel_out')
    assert probe.call(Trigger, '/sim_node/reset', Trigger.Request()).success
    base.hold((0.3, 0.0, 0.0), 0.5)                      # (ends with a stop: drive again)
    base.send(0.3, 0.0, 0.0)
    wait_for(lambda: applied and applied[-1][1].twist.linear.x > 0.25, 10.0,
             what='the base driving')
    bad = Twist()
    bad.linear.x, bad.angular.x = 0.3, math.nan
    base.pub.publish(bad)
    wait_for(lambda: applied[-1][1].twist.linear.x == 0.0, 10.0, what='the base stopped')
    t_stop = stamp_s(applied[-1][1].header.stamp)
    wait_for_stamp(base.odom, t_stop + 0.5, what='0.5 s of simulated time after the stop')
    assert [m.twist.linear.x for _, m in list(applied)
            if stamp_s(m.header.stamp) > t_stop] == []       # it stays stopped
    assert 'non-finite angular.x=nan' in youbot_sim.output()


def test_a_trajectory_of_huge_accelerations_is_refused_and_the_youbot_lives(youbot_sim, probe):
    """Issue 15, finding 1, as reported: 5 arm joints, two points, positions and velocities 0,
    the first point's accelerations 1e308 (finite), at 1 s and 2 s. It was accepted, its
    interpolation overflowed, PyBullet's state went NaN, and after ~/reset nothing moved. Now
    it is refused (the youBot's joint_limits.yaml: 6 rad/s^2), and so are accelerations of
    1e3 at the current position (which swung the arm 2.39 rad); odometry and joint states stay
    finite, the arm follows the next good trajectory and the base drives."""
    base = Base(probe)
    assert probe.call(Trigger, '/sim_node/reset', Trigger.Request()).success
    joints = probe.collect(JointState, '/youbot/joint_states')
    pub = probe.node.create_publisher(JointTrajectory, '/youbot/arm_controller/joint_trajectory',
                                      10)
    wait_for(lambda: joints and pub.get_subscription_count() > 0, 20.0, what='arm topics')

    def accelerating(first, second):
        msg = JointTrajectory(joint_names=list(JOINT_NAMES))
        for seconds, acc in ((1, first), (2, second)):
            point = JointTrajectoryPoint(positions=[0.0] * 5, velocities=[0.0] * 5,
                                         accelerations=[acc] * 5)
            point.time_from_start.sec = seconds
            msg.points.append(point)
        return msg

    pub.publish(accelerating(1e308, 0.0))
    wait_for(lambda: 'arm_joint_1 acceleration 1e+308 exceeds its limit 6' in youbot_sim.output(),
             10.0, what='the rejection')
    time.sleep(1.1)           # (rejections of one kind are logged a line a second at most)
    pub.publish(accelerating(1e3, -1e3))
    wait_for(lambda: 'arm_joint_1 acceleration 1000 exceeds its limit 6' in youbot_sim.output(),
             10.0, what='the second rejection')
    wait_for_stamp(joints, latest_stamp(joints) + 1.0, what='1 s of simulated time')
    odom = base.odom[-1][1].pose.pose.position
    assert all(math.isfinite(v) for v in (odom.x, odom.y, odom.z))
    assert np.all(np.isfinite(joints[-1][1].position))
    assert np.abs(_arm_positions(joints)).max() < 2e-3              # the arm never moved
    pub.publish(_trajectory((0.3, 0.2, 0.1, 0.0, 0.0), 1.0))
    wait_for(lambda: np.abs(_arm_positions(joints) - (0.3, 0.2, 0.1, 0.0, 0.0)).max() < 5e-3,
             20.0, what='the arm at the good trajectory\'s goal')
    x0, seen = _pose2d(base.odom[-1][1]).x, len(base.odom)
    base.hold((0.3, 0.0, 0.0), 1.0)
    # It drives at the commanded speed. (Not a distance over the hold: on a loaded machine this
    # process's commands arrive with gaps, and the simulator stops the base in each gap longer
    # than its command timeout, as it must.)
    assert max(m.twist.twist.linear.x for _, m in base.odom[seen:]) > 0.25
    assert _pose2d(base.odom[-1][1]).x - x0 > 0.1
    assert 'RuntimeWarning' not in youbot_sim.output() and youbot_sim.alive()
    pub.publish(_trajectory(np.zeros(5), 1.0))
