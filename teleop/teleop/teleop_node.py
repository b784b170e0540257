"""Keyboard teleop for the mini robot (the report's buttons), or a timed script of commands."""
from __future__ import annotations

import os
import select
import sys
import termios
import time
import tty
from typing import Optional

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.time import Time

from ros_common import early_stop
from ros_common.params import Param, declare_params
from ros_common.twist_out import TwistOut
from teleop.teleop_core import (
    HELP,
    HOLONOMIC_HELP,
    ScriptStep,
    TeleopError,
    TeleopScript,
    TeleopState,
    parse_script,
)

PARAMS = (
    Param('max_speed', 0.2, 'Speed at 100 % [m/s]', 1e-3, 10.0),
    Param('max_turn', 0.2, 'Turn rate at 100 % [rad/s]', 1e-3, 20.0),
    Param('speed', 0.5, 'Initial speed level, a fraction of max_speed and max_turn (the '
          'report: 0.5)', 0.0, 1.0),
    Param('publish_rate', 20.0, 'Rate of cmd_vel while a motion is active [Hz]', 0.5, 200.0),
    Param('holonomic', False, 'Strafe keys and statements (linear.y) for a Mecanum base'),
    Param('stamped', False, 'Publish geometry_msgs/TwistStamped instead of Twist'),
    Param('script', '', 'Timed commands, e.g. "forward 2s, left 1.5s, stop"; empty: keyboard'),
    Param('wait_for_subscriber', 10.0, 'Script mode: wall seconds to wait for a cmd_vel '
          'subscriber before starting', 0.0, 600.0),
)


class TeleopNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('teleop', **kwargs)
        p = declare_params(self, PARAMS)
        self.holonomic = p['holonomic']
        self.state = TeleopState(p['max_speed'], p['max_turn'], p['speed'],
                                 holonomic=self.holonomic)
        self.script: Optional[TeleopScript] = None
        if p['script'].strip():
            self.script = parse_script(p['script'], p['max_speed'], p['max_turn'],
                                       p['speed'], self.holonomic)
        self.wait_for_subscriber = p['wait_for_subscriber']
        self._out = TwistOut(self, 'cmd_vel', p['stamped'])
        self._pub = self._out.publisher
        self._script_start: Optional[Time] = None
        self._script_step: Optional[ScriptStep] = None
        self.finished = False
        self._timer = self.create_timer(1.0 / p['publish_rate'], self._on_timer)
        if self.script is not None:
            self._timer.cancel()  # started by start_script() once a subscriber is there
        self.get_logger().info(
            f'publishing on {self._pub.topic_name}; '
            + (f'script of {len(self.script.steps)} steps, {self.script.duration:.2f} s'
               if self.script else 'keyboard mode'))

    # --- keyboard mode ------------------------------------------------------------------
    def press(self, key: str) -> Optional[str]:
        change = self.state.press(key)
        if change is not None:
            self.publish_current()
        return change

    def _on_timer(self) -> None:
        if self.script is not None:
            self._script_tick()
            return
        if self.state.motion != 'stop':
            self.publish_current()

    def publish_current(self) -> None:
        vx, vy, wz = self.state.twist()
        self.publish_twist(vx, wz, vy)

    def publish_twist(self, v: float, w: float, vy: float = 0.0) -> None:
        self._out.publish(v, vy, w)

    def wait_for_delivery(self, timeout_sec: float) -> bool:
        """Wait until reliable subscribers acknowledged what was published (before exit)."""
        return self._pub.wait_for_all_acked(Duration(seconds=timeout_sec))

    def subscriber_count(self) -> int:
        return self._pub.get_subscription_count()

    @property
    def topic(self) -> str:
        """The resolved name of the topic it publishes on."""
        return self._pub.topic_name

    # --- script mode --------------------------------------------------------------------
    def start_script(self) -> None:
        self._script_start = None
        self._timer.reset()

    def _script_tick(self) -> None:
        if self.script is None:
            return
        now = self.get_clock().now()
        if now.nanoseconds == 0:
            return  # use_sim_time and no /clock yet
        if self._script_start is None:
            self._script_start = now
        elapsed = (now - self._script_start).nanoseconds * 1e-9
        step = self.script.command_at(elapsed)
        if step is None:
            self.publish_twist(0.0, 0.0)
            self.get_logger().info(f'script done after {elapsed:.2f} s')
            self._timer.cancel()
            self.finished = True
            return
        if step is not self._script_step:
            self._script_step = step
            self.get_logger().info(f't={elapsed:6.2f} s  {step.name:8s} v={step.v:+.3f} m/s '
                                   + (f'vy={step.vy:+.3f} m/s ' if self.holonomic else '')
                                   + f'w={step.w:+.3f} rad/s for {step.duration:g} s')
        self.publish_twist(step.v, step.w, step.vy)


def _running() -> bool:
    """Neither the context shut down nor a stop asked for (Ctrl-C, SIGTERM: early_stop)."""
    return rclpy.ok() and not early_stop.requested()


def _wait_for_subscriber(node: TeleopNode, executor, timeout: float) -> bool:
    # Wall time: with use_sim_time the clock does not run before the simulator does.
    end = time.monotonic() + timeout
    while time.monotonic() < end and _running():
        if node.subscriber_count() > 0:
            return True
        executor.spin_once(timeout_sec=0.05)
    return node.subscriber_count() > 0


def _run_script(node: TeleopNode, executor) -> int:
    if node.wait_for_subscriber > 0 and not _wait_for_subscriber(
            node, executor, node.wait_for_subscriber):
        if early_stop.requested():
            return 0
        node.get_logger().error(f'no subscriber on {node.topic} after '
                                f'{node.wait_for_subscriber:g} s; is the simulator running?')
        return 1
    node.start_script()
    while _running() and not node.finished:
        executor.spin_once(timeout_sec=0.1)
    return 0


def _run_keyboard(node: TeleopNode, executor) -> int:
    if not os.isatty(sys.stdin.fileno()):
        node.get_logger().error('stdin is not a terminal: run in a terminal, or give '
                                '-p script:="forward 2s, left 1.5s, stop"')
        return 1
    print(HELP + (HOLONOMIC_HELP if node.holonomic else ''), flush=True)
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    try:
        tty.setraw(fd)
        # One thread: poll the keyboard, then serve the executor (the repeat timer).
        while _running():
            executor.spin_once(timeout_sec=0.0)
            ready, _, _ = select.select([fd], [], [], 0.01)
            if not ready:
                continue
            key = os.read(fd, 1).decode(errors='ignore')
            if key in ('\x03', '\x04'):  # Ctrl-C, Ctrl-D
                break
            change = node.press(key)
            if change is not None:
                v, vy, w = node.state.twist()
                side = f' vy={vy:+.3f} m/s' if node.holonomic else ''
                sys.stdout.write(f'\r{change:12s} v={v:+.3f} m/s{side} w={w:+.3f} rad/s\r\n')
                sys.stdout.flush()
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
    return 0


def main(args=None) -> int:
    # A stop (SIGINT, SIGTERM) only sets a flag (early_stop, from the console script's first
    # line): the loops end at their next turn, within 0.1 s, and the zero twist goes out.
    # rclpy's handlers would shut the context down before it could; a KeyboardInterrupt raised
    # wherever the main thread is can leave one of rclpy's locks held, and the zero twist and
    # the shutdown then wait on it for ever.
    early_stop.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = TeleopNode()
    except (TeleopError, rclpy.exceptions.ParameterException) as exc:
        rclpy.logging.get_logger('teleop').fatal(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return 1
    if early_stop.requested():          # (stopped while the node was being made)
        node.destroy_node()
        rclpy.try_shutdown()
        return 0
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    code = 0
    try:
        code = _run_script(node, executor) if node.script else _run_keyboard(node, executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # Never leave the robot driving: a zero twist, whatever ended the session.
        if rclpy.ok():
            node.publish_twist(0.0, 0.0)
            node.wait_for_delivery(1.0)
        executor.shutdown(timeout_sec=0.5)
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
