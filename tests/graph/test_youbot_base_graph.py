"""The youBot's base over DDS, in lock-step: odometry follows cmd_vel (each command bound to
its steps, so that the machine's load cannot starve the sender past the command timeout)."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from std_srvs.srv import Trigger

from controllers.base_fidelity import tracking_errors
from controllers.diff_drive import Pose2D
from controllers.transforms import yaw_from_quaternion
from helpers import LockStepDriver, NodeProcess, stamp_s, wait_for

WORLD = 'world:=package://world_description/worlds/youbot.yaml'
# The most simulated time between two state messages: 100 Hz states on 240 Hz physics steps.
STATE_GAP = math.ceil(240 / 100) / 240
K = 0.386


def _pose2d(msg):
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    return Pose2D(p.x, p.y, yaw_from_quaternion((o.x, o.y, o.z, o.w)))


@pytest.fixture(scope='module')
def youbot_lockstep(tmp_path_factory):
    proc = NodeProcess('sim_node', ['-p', WORLD, '-p', 'synchronous:=true'],
                       tmp_path_factory.mktemp('youbot_lockstep'))
    yield proc
    proc.stop()


@pytest.mark.parametrize('command', [(0.2, 0.0, 0.0), (0.0, 0.2, 0.0), (0.0, 0.0, 0.5),
                                     (0.15, -0.1, 0.3)],
                         ids=['vx', 'vy', 'wz', 'combined'])
def test_base_odometry_follows_cmd_vel(youbot_lockstep, probe, command):
    """The base moves as the command it takes says, over the stretch in which its wheels held
    that command (``cmd_vel_out``), from 0.15 s after they reached it. Driven in lock-step, each
    command bound to its steps: paced in real time, a sender starved on a busy machine missed
    the command timeout, and the base rightly stopped (the sender's fault, not the base's)."""
    driver = LockStepDriver(probe, robot='youbot')
    applied = probe.collect(TwistStamped, '/youbot/cmd_vel_out')
    assert probe.call(Trigger, '/sim_node/reset', Trigger.Request()).success
    t_cmd = stamp_s(driver.reply(driver.step(1)).sim_time)
    vx, vy, wz = command
    driver.hold(vx, wz, round(2.8 * 240), vy=vy)       # (re-sent every 0.1 s of sim time)
    driver.hold(0.0, 0.0, 24)
    wait_for(lambda: applied and stamp_s(applied[-1][1].header.stamp) >= t_cmd + 2.8, 10.0,
             what='the stop in cmd_vel_out')
    changes = sorted((stamp_s(m.header.stamp), (m.twist.linear.x, m.twist.linear.y,
                                                m.twist.angular.z)) for _, m in list(applied))
    held = [(t, t_next) for (t, c), (t_next, _) in zip(changes, changes[1:])
            if t >= t_cmd and np.allclose(c, command, atol=1e-9)]
    start, end = max(held, key=lambda span: span[1] - span[0])
    start, end = start + 0.15, min(end, t_cmd + 2.8)
    assert end - start >= 2.0, (held, command)       # (the ramp at the limits: < 0.5 s)
    base = driver
    # (Odometry travels on its own writer: it may come in after cmd_vel_out of a later time.)
    wait_for(lambda: stamp_s(base.odom[-1][1].header.stamp) >= end, 10.0,
             what='the odometry up to the end of the stretch')
    window = [m for _, m in list(base.odom) if start <= stamp_s(m.header.stamp) <= end]
    first, last = window[0], window[-1]
    duration = stamp_s(last.header.stamp) - stamp_s(first.header.stamp)
    # None missing: states go out at the first physics step on or after each 10 ms grid point,
    # so two are at most STATE_GAP apart, and the window's edges at most that far inside it.
    stamps = [stamp_s(m.header.stamp) for m in window]
    assert max(np.diff(stamps)) <= STATE_GAP + 1e-6
    assert stamps[0] - start <= STATE_GAP + 1e-6 and end - stamps[-1] <= STATE_GAP + 1e-6
    twist = np.mean([(m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z)
                     for m in window], axis=0)
    e = tracking_errors(command, duration, _pose2d(first), _pose2d(last), tuple(twist), K)
    assert e.twist_error < 0.03 and e.position_error < 0.03 and e.yaw_error < 0.03
    assert e.cross_drift < 0.02
    assert youbot_lockstep.alive()
