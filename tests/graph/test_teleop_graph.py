"""The teleop node: keyboard mode through a pseudo-terminal, and timed scripts."""
import os
import pty
import signal
import time

import pytest
from geometry_msgs.msg import Twist

from helpers import wait_for


@pytest.fixture
def cmd_vel(probe):
    return probe.collect(Twist, '/mini_robot/cmd_vel')


def _twist(msg):
    return round(msg.linear.x, 6), round(msg.angular.z, 6)


def _twist3(msg):
    return round(msg.linear.x, 6), round(msg.linear.y, 6), round(msg.angular.z, 6)


def _start_keyboard(start_node, probe, *extra):
    master, slave = pty.openpty()
    proc = start_node('teleop', '-r', '__ns:=/mini_robot', '-p', 'publish_rate:=20.0', *extra,
                      stdin=slave)
    os.close(slave)
    wait_for(lambda: 'Mini robot teleop' in proc.output(), 15.0, what='key help')
    wait_for(lambda: probe.node.count_publishers('/mini_robot/cmd_vel') > 0, 10.0,
             what='teleop publisher')
    return master, proc


def test_keyboard_buttons_speed_and_zero_on_ctrl_c(start_node, probe, cmd_vel):
    master, proc = _start_keyboard(start_node, probe)
    try:
        os.write(master, b'i')
        wait_for(lambda: cmd_vel and _twist(cmd_vel[-1][1]) == (0.1, 0.0), 5.0,
                 what='forward at half speed')
        # Repeats at the publish rate while the motion is active.
        n = len(cmd_vel)
        wait_for(lambda: len(cmd_vel) >= n + 10, 5.0, what='repeated commands')
        os.write(master, b'+')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.12, 0.0), 5.0, what='speed up')
        os.write(master, b'j')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.0, 0.12), 5.0, what='turn left')
        os.write(master, b'l')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.0, -0.12), 5.0, what='turn right')
        os.write(master, b',')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (-0.12, 0.0), 5.0, what='backward')
        os.write(master, b'k')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.0, 0.0), 5.0, what='stop')
        # Stopped: the repeats end (six publish periods of silence).
        n = len(cmd_vel)
        time.sleep(0.3)
        assert len(cmd_vel) == n
        os.write(master, b'w')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.12, 0.0), 5.0, what='forward again')
        os.write(master, b'\x03')  # Ctrl-C in raw mode
        wait_for(lambda: not proc.alive(), 10.0, what='teleop to exit')
        assert proc.proc.returncode == 0
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.0, 0.0), 5.0, what='final zero twist')
    finally:
        os.close(master)


def test_sigint_sends_a_zero_twist(start_node, probe, cmd_vel):
    master, proc = _start_keyboard(start_node, probe)
    try:
        os.write(master, b'w')
        wait_for(lambda: cmd_vel and _twist(cmd_vel[-1][1]) == (0.1, 0.0), 5.0,
                 what='forward')
        proc.proc.send_signal(signal.SIGINT)
        wait_for(lambda: not proc.alive(), 10.0, what='teleop to exit')
        wait_for(lambda: _twist(cmd_vel[-1][1]) == (0.0, 0.0), 5.0, what='final zero twist')
    finally:
        os.close(master)


def test_holonomic_mode_strafes_with_linear_y(start_node, probe, cmd_vel):
    master, proc = _start_keyboard(start_node, probe, '-p', 'holonomic:=true')
    try:
        assert 'strafe left' in proc.output()
        os.write(master, b'J')
        wait_for(lambda: cmd_vel and _twist3(cmd_vel[-1][1]) == (0.0, 0.1, 0.0), 5.0,
                 what='strafe left')
        os.write(master, b'e')
        wait_for(lambda: _twist3(cmd_vel[-1][1]) == (0.0, -0.1, 0.0), 5.0, what='strafe right')
        os.write(master, b'\x03')
        wait_for(lambda: not proc.alive(), 10.0, what='teleop to exit')
        wait_for(lambda: _twist3(cmd_vel[-1][1]) == (0.0, 0.0, 0.0), 5.0, what='zero twist')
    finally:
        os.close(master)


def test_script_mode_runs_the_commands_in_order(start_node, cmd_vel):
    proc = start_node('teleop', '-r', '__ns:=/mini_robot', '-p',
                      'script:=forward 0.5s, speed 1.0, left 0.5s, stop', '-p',
                      'publish_rate:=20.0')
    wait_for(lambda: not proc.alive(), 20.0, what='the script to finish')
    assert proc.proc.returncode == 0
    twists = [_twist(m) for _, m in cmd_vel]
    forward = twists.count((0.1, 0.0))
    left = twists.count((0.0, 0.2))
    # 0.5 s at 20 Hz each (the first and last tick may fall either side of a boundary).
    assert 9 <= forward <= 12 and 9 <= left <= 12
    assert twists.index((0.0, 0.2)) > twists.index((0.1, 0.0))
    assert twists[-1] == (0.0, 0.0)
    assert 'script done' in proc.output()


@pytest.mark.parametrize('args, fragment', [
    (['-p', 'script:=forward 2s, jump 1s'], 'unknown command "jump"'),
    (['-p', 'speed:=2.0'], 'cannot start'),
    ([], 'stdin is not a terminal'),
])
def test_bad_input_fails_clearly(start_node, args, fragment):
    proc = start_node('teleop', *args)
    wait_for(lambda: not proc.alive(), 15.0, what='teleop to exit')
    assert proc.proc.returncode == 1
    assert fragment in proc.output()


def test_script_without_a_subscriber_gives_up_clearly(start_node):
    proc = start_node('teleop', '-r', '__ns:=/nobody', '-p', 'script:=forward 1s', '-p',
                      'wait_for_subscriber:=1.0')
    wait_for(lambda: not proc.alive(), 15.0, what='teleop to exit')
    assert proc.proc.returncode == 1
    assert 'no subscriber' in proc.output()
