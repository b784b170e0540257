"""The simulator node as a user drives it: separate processes over DDS, in simulated time."""
import math
import re
import time

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from sim_interfaces.srv import StepSimulation
from std_srvs.srv import Trigger

from controllers.transforms import yaw_from_quaternion
from helpers import LockStepDriver, stamp_s, wait_for

RTF = 4.0   # paced, but faster than real time to keep the suite short
DT = 1.0 / 240.0
DT_NS = round(DT * 1e9)  # simulated time advances in whole nanoseconds per step


class ClockWatch:
    """Follows /clock, as a user's node would. (Tests of a robot's response to commands drive
    the simulator in lock-step, with ``LockStepDriver``: paced at 4x, a second of simulated
    time is 0.25 s of wall time, and a busy machine let whole commanded intervals pass with no
    command delivered.)"""

    def __init__(self, probe):
        self.clock = probe.collect(Clock, '/clock')
        wait_for(lambda: self.clock, 15.0, what='/clock')

    def now(self):
        return stamp_s(self.clock[-1][1].clock)


def _ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.fixture
def sim(start_node):
    return start_node('sim_node', '-p', f'real_time_factor:={RTF}', '-p', 'rtf_log_period:=1.0')


@pytest.fixture
def lockstep(start_node, probe):
    """A lock-step simulator driven with announced commands: the distances below are then
    exactly those of the commanded intervals, however busy the machine is."""
    start_node('sim_node', '-p', 'synchronous:=true', '-p', 'state_publish_rate:=240.0')
    return LockStepDriver(probe)


def _pose(msg):
    p = msg.pose.pose
    return p.position.x, p.position.y, yaw_from_quaternion(
        (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w))


def test_forward_0p1_for_2s_gives_0p2_m(lockstep, probe):
    joints = probe.collect(JointState, '/mini_robot/joint_states')
    x0, y0, _ = _pose(lockstep.odom_at(lockstep.hold(0.0, 0.0, 72).sim_time))   # settled
    lockstep.hold(0.1, 0.0, 480)                                                 # 2 s
    last = lockstep.hold(0.0, 0.0, 240)                                          # stopped
    end = lockstep.odom_at(last.sim_time)
    assert abs(end.twist.twist.linear.x) < 1e-3                                  # at rest
    x, y, yaw = _pose(end)
    assert x - x0 == pytest.approx(0.2, rel=0.05)
    assert abs(y - y0) < 0.005 and abs(yaw) < 0.02
    # The wheels turned by rolling: about 0.2 m / r of wheel angle.
    wait_for(lambda: any(m.header.stamp == last.sim_time for _, m in joints), 10.0,
             what='the joint states of the last step')
    state = next(m for _, m in joints if m.header.stamp == last.sim_time)
    left = state.position[list(state.name).index('left_wheel_joint')]
    assert left == pytest.approx(0.2 / 0.03, rel=0.05)


def test_turn_in_place_for_pi_over_0p2_s_gives_pi(lockstep):
    lockstep.hold(0.0, 0.0, 72)
    start = len(lockstep.odom) - 1
    lockstep.hold(0.0, 0.2, round(math.pi / 0.2 * 240))
    last = lockstep.hold(0.0, 0.0, 240)
    end = lockstep.odom_at(last.sim_time)
    assert abs(end.twist.twist.angular.z) < 1e-3
    yaws = [_pose(m)[2] for _, m in lockstep.odom[start:]]
    turned = np.unwrap(yaws)[-1] - yaws[0]
    assert turned == pytest.approx(math.pi, rel=0.05)
    x, y, _ = _pose(end)
    assert math.hypot(x, y) < 0.01


def _lock_step_sim(start_node, *params):
    return start_node('sim_node', '-p', 'synchronous:=true', '-p', 'state_publish_rate:=240.0',
                      *params)


def _twist_after(driver, vx, wz, seconds=1.0, vy=0.0):
    """The odometry twist after ``seconds`` of (vx, vy, wz), in lock-step: the commands apply
    to exactly those steps, however starved this process is (paced at 4x, a second of
    simulated time is 0.25 s of wall time, and a busy machine let it pass with no command)."""
    return driver.odom_at(driver.hold(vx, wz, round(seconds / DT), vy=vy).sim_time).twist.twist


def test_commands_above_the_limits_are_clamped(start_node, probe):
    sim = _lock_step_sim(start_node)
    d = LockStepDriver(probe)
    d.hold(0.0, 0.0, 72)
    assert _twist_after(d, 1.0, 0.0).linear.x == pytest.approx(0.2, rel=0.03)
    d.hold(0.0, 0.0, 240)
    assert _twist_after(d, 0.0, -3.0).angular.z == pytest.approx(-0.2, rel=0.03)
    wait_for(lambda: 'clamped to (0.200, 0.000)' in sim.output(), 5.0, what='clamp warning')


def test_silence_past_the_timeout_stops_the_robot(start_node, probe):
    sim = start_node('sim_node', '-p', 'synchronous:=true', '-p', 'state_publish_rate:=240.0')
    applied = probe.collect(TwistStamped, '/mini_robot/cmd_vel_out')
    lockstep = LockStepDriver(probe)
    last = lockstep.hold(0.1, 0.0, 240)
    # The last command arrived before the last batch of 24 steps ran.
    t_command = stamp_s(last.sim_time) - 24 * DT
    assert lockstep.odom_at(last.sim_time).twist.twist.linear.x == pytest.approx(0.1, rel=0.05)
    # No zero twist is sent: only the timeout (0.5 s) can stop it.
    quiet = lockstep.reply(lockstep.step(240))
    assert abs(lockstep.odom_at(quiet.sim_time).twist.twist.linear.x) < 1e-3
    stopped_at = next(stamp_s(m.header.stamp) for _, m in lockstep.odom
                      if stamp_s(m.header.stamp) > t_command + 0.1
                      and abs(m.twist.twist.linear.x) < 0.01)
    # Braking takes 0.1 s at the world's 1 m/s^2 (max_accel).
    assert t_command + 0.5 < stopped_at < t_command + 0.7
    wait_for(lambda: 'stopping' in sim.output(), 5.0, what='timeout log line')
    # cmd_vel_out says what the wheels followed, and when: 0.1 m/s once the ramp from rest
    # reached it, a ramp down from the moment the timeout passed, zero at its end.
    wait_for(lambda: applied and applied[-1][1].twist.linear.x == 0.0, 5.0, what='cmd_vel_out')
    values = [(stamp_s(m.header.stamp), m.twist.linear.x) for _, m in applied]
    cruise = [t for t, x in values if x == pytest.approx(0.1)]
    braking = [t for t, x in values if t > cruise[-1]]
    assert cruise and braking[0] - t_command == pytest.approx(0.5, abs=2 * DT)
    assert braking[-1] - t_command == pytest.approx(0.6, abs=2 * DT)
    assert all(b < a for (_, a), (_, b) in zip(values[-len(braking) - 1:], values[-len(braking):]))
    stop = applied[-1][1]
    assert stop.header.frame_id == 'base_link'


def test_nan_is_rejected_the_robot_stops_and_the_node_lives(start_node, probe):
    from diagnostic_msgs.msg import DiagnosticArray
    sim = start_node('sim_node', '-p', 'synchronous:=true', '-p', 'state_publish_rate:=240.0')
    diagnostics = probe.collect(DiagnosticArray, '/diagnostics')
    lockstep = LockStepDriver(probe)
    lockstep.hold(0.1, 0.0, 120)
    lockstep.send(math.nan, 0.0)
    # 0.25 s, well inside the 0.5 s timeout: only the rejection can stop it.
    after = lockstep.reply(lockstep.step(60, commands=1))
    assert after.success, after.message
    assert abs(lockstep.odom_at(after.sim_time).twist.twist.linear.x) < 2e-3
    assert sim.alive()
    lockstep.send(0.0, math.inf)
    assert lockstep.reply(lockstep.step(1, commands=1)).success
    wait_for(lambda: 'cmd_vel rejected: non-finite angular.z=inf' in sim.output(), 5.0,
             what='rejection warning')
    again = lockstep.hold(0.1, 0.0, 120)
    assert lockstep.odom_at(again.sim_time).twist.twist.linear.x == pytest.approx(0.1, rel=0.05)
    # The sender is told too (issue 15, finding 6): /diagnostics, once a second, counts every
    # rejection per input and kind and gives the last reason.
    def cmd_vel_status():
        found = [st for _, m in diagnostics for st in m.status
                 if st.name == 'sim_node: mini_robot/cmd_vel']
        return found[-1] if found else None
    def values():
        status = cmd_vel_status()
        return {kv.key: kv.value for kv in status.values} if status else {}
    wait_for(lambda: values().get('non-finite') == '2', 5.0, what='/diagnostics')
    status = cmd_vel_status()
    assert status.hardware_id == 'mini_robot'
    assert values() == {'non-finite': '2',
                      'last reason': 'mini_robot/cmd_vel rejected: non-finite angular.z=inf; '
                                     'stopping'}
    wait_for(lambda: cmd_vel_status().level == b'\x00', 5.0, what='OK once quiet')


def test_sideways_velocity_on_a_diff_drive_is_ignored_with_a_warning(start_node, probe):
    sim = _lock_step_sim(start_node)
    d = LockStepDriver(probe)
    d.hold(0.0, 0.0, 72)
    twist = _twist_after(d, 0.1, 0.0, 0.5, vy=0.1)
    assert twist.linear.x == pytest.approx(0.1, rel=0.05)
    assert abs(twist.linear.y) < 0.005
    wait_for(lambda: 'cannot move sideways' in sim.output(), 5.0, what='the warning')


def test_clock_advances_at_the_paced_rate(sim, probe):
    clock = probe.collect(Clock, '/clock')
    wait_for(lambda: len(clock) > 10, 10.0, what='/clock')
    time.sleep(1.0)
    received = clock[5:]  # after discovery settled
    (_, c0), (_, c1) = received[0], received[-1]
    ns = np.array([_ns(c.clock) for _, c in received])
    gaps = np.diff(ns)
    assert (gaps > 0).all()
    # One /clock per physics step (clock_publish_rate 0, the default): every gap is a whole
    # number of steps, nearly all exactly one (a reliable queue may drop one when the probe
    # process is starved).
    assert (gaps % DT_NS == 0).all()
    assert np.mean(gaps == DT_NS) > 0.95
    # Paced: simulated time never runs ahead of the factor, as the simulator measures it over
    # its steps (receive times in this process say little when the machine is busy: a starved
    # probe takes a burst of queued messages at once). How close to the factor it comes
    # depends on the load, so only the bound is checked; bench/ measures the rate.
    assert stamp_s(c1.clock) > stamp_s(c0.clock)
    measured = re.compile(r'real-time factor ([0-9.]+) \(sim time')
    wait_for(lambda: len(measured.findall(sim.output())) >= 2, 10.0, what='RTF log lines')
    rtfs = [float(v) for v in measured.findall(sim.output())]
    assert all(0.0 < rtf < 1.05 * RTF for rtf in rtfs), rtfs


def test_camera_info_matches_the_image(sim, probe):
    images = probe.collect(Image, '/mini_robot/camera/image_raw', qos_profile_sensor_data)
    infos = probe.collect(CameraInfo, '/mini_robot/camera/camera_info', qos_profile_sensor_data)

    def pairs():
        # An image and the camera_info of the same stamp. The two topics are delivered
        # independently (best effort): the info of the latest image may not be in yet, or lost.
        by_stamp = {stamp_s(m.header.stamp): m for _, m in list(infos)}
        return [(m, by_stamp[stamp_s(m.header.stamp)]) for _, m in list(images)
                if stamp_s(m.header.stamp) in by_stamp]
    wait_for(lambda: len(images) >= 5 and len(pairs()) >= 3, 20.0, what='camera frames')
    img, info = pairs()[-1]
    assert (img.width, img.height, img.encoding) == (320, 240, 'rgb8')
    assert (info.width, info.height) == (img.width, img.height)
    assert img.step == 3 * img.width and len(img.data) == img.step * img.height
    assert img.header.frame_id == info.header.frame_id == 'camera_optical_frame'
    fx, cx, cy = info.k[0], info.k[2], info.k[5]
    assert fx == pytest.approx(120.0 / math.tan(math.radians(30.0)))
    assert (cx, cy) == (160.0, 119.0)
    pixels = np.frombuffer(img.data, np.uint8).reshape(240, 320, 3)
    assert pixels.std() > 5  # a rendered scene, not a blank buffer
    # 15 Hz of simulated time.
    stamps = [stamp_s(m.header.stamp) for _, m in images]
    assert np.median(np.diff(stamps)) == pytest.approx(1 / 15, abs=DT)


def test_camera_info_alone_is_published_without_rendering(sim, probe):
    infos = probe.collect(CameraInfo, '/mini_robot/camera/camera_info', qos_profile_sensor_data)
    wait_for(lambda: len(infos) >= 3, 20.0, what='camera_info without an image subscriber')
    assert (infos[-1][1].width, infos[-1][1].height) == (320, 240)


def test_reset_returns_the_robot_to_its_start_pose(start_node, probe):
    _lock_step_sim(start_node)
    d = LockStepDriver(probe)
    moved = d.odom_at(d.hold(0.2, 0.2, 360).sim_time).pose.pose.position
    assert math.hypot(moved.x, moved.y) > 0.1
    reply = probe.call(Trigger, '/sim_node/reset', Trigger.Request())
    assert reply.success
    # At the start pose on the next step, and it stays there.
    for steps in (1, 72):
        odom = d.odom_at(d.hold(0.0, 0.0, steps).sim_time)
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        assert math.hypot(p.x, p.y) < 0.002, steps
        assert abs(yaw_from_quaternion((q.x, q.y, q.z, q.w))) < 0.01, steps


def test_pause_resume_and_step_while_paused(sim, probe):
    d = ClockWatch(probe)
    refused = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=5))
    assert not refused.success and 'paused' in refused.message
    assert probe.call(Trigger, '/sim_node/pause', Trigger.Request()).success
    # While paused, a step request is served and tells the exact simulated time.
    one = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=1))
    assert one.success
    wait_for(lambda: d.clock[-1][1].clock == one.sim_time, 5.0, what='the stepped /clock')
    time.sleep(0.3)  # paused: nothing advances over this window
    assert d.clock[-1][1].clock == one.sim_time
    reply = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=24))
    assert reply.success and _ns(reply.sim_time) == _ns(one.sim_time) + 24 * DT_NS
    # A resume while a long step request is served is refused: both stepping, the reply
    # counted 61,888 steps for a request of 60,000.
    client = probe.node.create_client(StepSimulation, '/sim_node/step')
    probe.service(Trigger, '/sim_node/resume', 30.0)  # (found before, not while it runs)
    long = client.call_async(StepSimulation.Request(steps=24000))
    wait_for(lambda: d.now() > stamp_s(reply.sim_time) + 0.1, 30.0, what='the long step to run')
    busy = probe.call(Trigger, '/sim_node/resume', Trigger.Request())
    assert not busy.success and 'steps left' in busy.message
    wait_for(long.done, 120.0, what='the long step')
    assert long.result().success
    assert _ns(long.result().sim_time) == _ns(reply.sim_time) + 24000 * DT_NS
    t_paused = stamp_s(long.result().sim_time)
    assert probe.call(Trigger, '/sim_node/resume', Trigger.Request()).success
    wait_for(lambda: d.now() > t_paused + 0.5, 5.0, what='time after resume')


def test_stamped_velocity_commands(start_node, probe):
    _lock_step_sim(start_node, '-p', 'use_stamped_vel:=true')
    d = LockStepDriver(probe, stamped=True)
    d.hold(0.0, 0.0, 72)
    assert _twist_after(d, 0.1, 0.0, 0.5).linear.x == pytest.approx(0.1, rel=0.05)


@pytest.mark.parametrize('clock_rate', [0.0, 100.0])
def test_lock_step_advances_exactly_n_steps_per_request(start_node, probe, clock_rate):
    start_node('sim_node', '-p', 'synchronous:=true', '-p', f'clock_publish_rate:={clock_rate}')
    clock = probe.collect(Clock, '/clock')
    odom = probe.collect(Odometry, '/mini_robot/odom')
    first = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=1))
    assert first.success
    time.sleep(0.5)  # no request, no physics
    again = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=1))
    assert again.step_count == first.step_count + 1
    for n in (1, 7, 240, 1000):
        before = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=1))
        n_clock = len(clock)
        reply = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=n))
        assert reply.success
        assert reply.step_count == before.step_count + n
        assert _ns(reply.sim_time) == _ns(before.sim_time) + n * DT_NS
        # The steps' messages were published before the reply: the last /clock is its time
        # (at the end of every request, on the clock's grid or not).
        wait_for(lambda reply=reply: clock[-1][1].clock == reply.sim_time, 5.0,
                 what='the final /clock')
        if n <= 7:
            # Well within the publisher's history depth every message arrives: one per step,
            # or one per 10 ms slot and the request's end.
            time.sleep(0.1)
            if clock_rate == 0.0:
                assert len(clock) == n_clock + n
            else:
                start, end = _ns(before.sim_time), _ns(reply.sim_time)
                slots = end // 10_000_000 - start // 10_000_000
                assert len(clock) - n_clock in (slots, slots + 1)
    # States at 100 Hz: the last odom published is at most one state period old.
    assert stamp_s(reply.sim_time) - stamp_s(odom[-1][1].header.stamp) < 0.0105
    bad = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=100_001))
    assert not bad.success and 'within' in bad.message
    # 0 steps: a round trip that takes none (a client's first, which it may send again).
    none = probe.call(StepSimulation, '/sim_node/step', StepSimulation.Request(steps=0))
    assert none.success and none.step_count == reply.step_count
    assert not probe.call(Trigger, '/sim_node/pause', Trigger.Request()).success


@pytest.mark.parametrize('args, fragment', [
    (['-p', 'time_step:=1.0'], 'bad parameter'),
    (['-p', 'world:=/nonexistent/world.yaml'], 'does not exist'),
    (['-p', 'max_speed:=fast'], 'bad parameter'),
])
def test_bad_parameters_fail_at_start_with_a_clear_message(start_node, args, fragment):
    proc = start_node('sim_node', *args)
    wait_for(lambda: not proc.alive(), 15.0, what='the node to exit')
    assert proc.proc.returncode == 1
    assert fragment in proc.output()


def test_a_stamped_command_too_old_or_from_the_future_is_rejected(start_node, probe):
    """Issue 15, finding 5: a TwistStamped stamped -5 s or 2**31 - 1 s was applied as fresh. Now
    its stamp is judged against the simulator's clock, as diff_drive_controller does."""
    from geometry_msgs.msg import TwistStamped
    sim = _lock_step_sim(start_node, '-p', 'use_stamped_vel:=true')
    d = LockStepDriver(probe, stamped=True)
    moving = d.hold(0.1, 0.0, 120)                       # (unset stamps: taken as now)
    now = stamp_s(moving.sim_time)
    assert d.odom_at(moving.sim_time).twist.twist.linear.x == pytest.approx(0.1, rel=0.05)
    for stamp, why in ((now - 5.0, 'stamped -4'), (2 ** 31 - 1, 'stamped 2147483647.000 s')):
        msg = TwistStamped()
        msg.twist.linear.x = 0.1
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(stamp), 0
        d.pub.publish(msg)
        after = d.reply(d.step(60, commands=1))          # 0.25 s: inside the timeout
        assert abs(d.odom_at(after.sim_time).twist.twist.linear.x) < 2e-3, stamp
        wait_for(lambda why=why: why in sim.output(), 5.0, what='the rejection')
        d.hold(0.1, 0.0, 120)                             # a fresh command drives again
    assert "is the sender on simulated time?" in sim.output()
    # A stamp of now is taken.
    msg = TwistStamped()
    msg.twist.linear.x = 0.1
    last = d.hold(0.0, 0.0, 24)
    msg.header.stamp = last.sim_time
    d.pub.publish(msg)
    taken = d.reply(d.step(60, commands=1))
    assert d.odom_at(taken.sim_time).twist.twist.linear.x == pytest.approx(0.1, rel=0.1)


@pytest.mark.parametrize('rtf', ['0.0', '1.0'])
def test_ctrl_c_ends_a_running_simulator_cleanly(start_node, probe, rtf):
    """SIGINT while the simulator steps (as fast as it can, or in real time): it ended with
    "[FATAL] Exception in 'timers' callback: Failed to publish: publisher's context is invalid"
    in about one run of six. Each run here stops it mid-step."""
    clock = probe.collect(Clock, '/clock', qos=10)
    for run in range(4):
        clock.clear()
        sim = start_node('sim_node', '-p', f'real_time_factor:={rtf}', name=f'sim_{run}')
        wait_for(lambda: len(clock) > 50, 60.0, what='the simulator to step')
        assert sim.stop() == 0, sim.output()[-2000:]
        assert not [line for line in sim.output().splitlines()
                    if line.startswith(('[FATAL]', '[ERROR]', 'Traceback'))], sim.output()[-2000:]
