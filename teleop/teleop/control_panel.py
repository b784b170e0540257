"""``control_panel``: the mini robot report's interface as a web page, served on
``http://127.0.0.1:8080``.

The page (``teleop/web/``) has the report's buttons and speed slider, the teleop node's keys,
strafe buttons for a holonomic base, the live camera image, an odometry readout with the path
drawn and, when the pipeline coordinator runs, each material's status, the robots' states and
the elapsed time. The robot is chosen on the page, from the simulator's world.

HTTP and the page's WebSocket (``/ws``) are served by ``panel_server.PanelServer`` in a thread
of its own; the ROS side (publishing ``cmd_vel``, reading odometry, the camera's JPEG frames and
the coordinator) runs in the node's executor. The dead-man rule is ``panel_core.DeadMan``.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.subscription import Subscription
from sensor_msgs.msg import CompressedImage
from sim_interfaces.msg import PipelineEvent, PipelineState

from ros_common.geometry import yaw_of
from ros_common.log_limit import KeyedLimiter
from ros_common.node_main import run_node
from ros_common.params import Param, declare_params, declare_web_access
from ros_common.stamps import to_seconds
from ros_common.twist_out import TwistOut
from ros_common.web_access import WebAccessError
from teleop.panel_core import (
    DeadMan,
    PanelInputError,
    PanelRobot,
    parse_command,
    robots_of_world,
)
from teleop.panel_server import PanelServer, PanelServerError
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world

PATH_POINTS = 2000          # odometry points kept for the drawn path
PATH_STEP_M = 0.005         # a new path point once the robot moved this far


PARAMS = (
    Param('host', '127.0.0.1', 'Address to serve the page on; loopback unless told otherwise '
          '(anyone who reaches it can drive the robots)'),
    Param('port', 8080, 'TCP port of the page (0: any free port)', 0, 65535),
    Param('simulator', '/sim_node', 'The simulator node whose world lists the robots'),
    Param('namespace', '', 'The robot driven at start (its namespace); empty: the first base '
          'of the world'),
    Param('speed', 0.5, "The slider's start: a fraction of max_speed (the report's buttons: "
          '0.5)', 0.0, 1.0),
    Param('report_turns', False, "The report's turn buttons: wheels at +-speed*max_speed/r (a "
          'diff drive turns at 2*speed*max_speed/wheel_separation) instead of speed*max_turn'),
    Param('deadman_timeout', 0.3, 'Wall seconds without word from the page that holds a button '
          'before the robot is stopped (the page repeats every 0.1 s)', 0.05, 5.0),
    Param('publish_rate', 20.0, 'Rate of cmd_vel while a button is held [Hz]', 1.0, 200.0),
    Param('stamped', False, 'Publish geometry_msgs/TwistStamped instead of Twist'),
    Param('camera_rate', 5.0, 'Camera frames sent to the page per second', 0.1, 30.0),
    Param('max_speed', 0.2, 'Speed at 100 % where neither the world nor the simulator says '
          '[m/s]', 1e-3, 10.0),
    Param('max_turn', 0.2, 'Turn rate at 100 % where neither the world nor the simulator says '
          '[rad/s]', 1e-3, 20.0),
)


class ControlPanelError(RuntimeError):
    """The panel cannot start (a bad access rule)."""


class ControlPanel(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('control_panel', **kwargs)
        p = declare_params(self, PARAMS)
        self._lock = threading.Lock()
        self._wanted_ns = p['namespace']
        self._speed0, self._report_turns0 = float(p['speed']), bool(p['report_turns'])
        self._deadman_timeout = float(p['deadman_timeout'])
        self._stamped = bool(p['stamped'])
        self._fallback = (float(p['max_speed']), float(p['max_turn']))
        self._camera_period = 1.0 / float(p['camera_rate'])
        self.robots: List[PanelRobot] = []
        self.drive: Optional[DeadMan] = None
        self._out: Optional[TwistOut] = None
        self._odom_sub: Optional[Subscription] = None
        self._camera_sub: Optional[Subscription] = None
        self._odom: Optional[Dict[str, float]] = None
        self._path: List[Tuple[float, float]] = []
        self._jpeg: Optional[bytes] = None
        self._jpeg_at = -math.inf       # (time.monotonic() of the last frame taken)
        self._coordinator: Optional[Dict[str, Any]] = None
        self._materials: Dict[int, Dict[str, Any]] = {}
        self.last_error = ''
        # A robot chosen on a page, made the driven one at the next tick (the latest of a
        # flood of choices only), and a hello owed to the pages (their view of the settings).
        self._wanted_robot: Optional[PanelRobot] = None
        self._hello_due = False
        # A line a second per page for its refused messages, saying how many it stands for
        # (rclpy's own throttle costs 0.75 ms a call even when it holds a line back: a flood
        # of 3,000 bad messages held the page's keepalive pong back 2.8 s).
        self._refusal_log = KeyedLimiter(1.0)
        host = p['host']
        try:
            access, max_pages = declare_web_access(
                self, host, (), "empty: only the panel's own page may drive", 'max_pages',
                'Pages')
        except WebAccessError as exc:
            raise ControlPanelError(str(exc)) from None
        self._access = access
        self._server = PanelServer(self, self.get_logger(), host, int(p['port']), access,
                                   max_pages)
        self.url = self._server.url
        # The world, from the simulator: asked until it answers.
        self._sim = p['simulator']
        self._params = self.create_client(GetParameters, f'{self._sim}/get_parameters')
        self._asking = False
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._ask_timer = self.create_timer(1.0, self._ask_world, clock=steady)
        self.create_timer(1.0 / float(p['publish_rate']), self._tick, clock=steady)
        self.create_timer(0.1, self._telemetry, clock=steady)
        self.create_subscription(PipelineState, '/coordinator_node/state', self._on_state,
                                 QoSProfile(depth=1, durability=1))
        self.create_subscription(PipelineEvent, '/coordinator_node/events', self._on_event,
                                 QoSProfile(depth=100))
        self.get_logger().info(f'serving the control panel on {self.url} (to '
                               f'{self._access.describe()}); waiting for the world of '
                               f'{self._sim}')
        self._ask_world()

    # --- the robots ---------------------------------------------------------------------------
    def _ask_world(self) -> None:
        if self.robots or self._asking or not self._params.service_is_ready():
            return
        self._asking = True
        future = self._params.call_async(GetParameters.Request(
            names=['world', 'max_speed', 'max_turn']))
        future.add_done_callback(self._on_world)

    def _on_world(self, future) -> None:
        self._asking = False
        values = future.result().values if future.result() is not None else []
        robots = self._robots_of(values)
        if not robots:
            return
        self._ask_timer.cancel()
        with self._lock:
            self.robots = robots
        chosen = next((r for r in robots if r.namespace == '/' + self._wanted_ns.strip('/')),
                      robots[0])
        if self._wanted_ns and chosen.namespace != '/' + self._wanted_ns.strip('/'):
            self.get_logger().warn(f'no base in namespace {self._wanted_ns}; driving '
                                   f'{chosen.namespace}')
        self.get_logger().info('robots: ' + ', '.join(
            f'{r.name} ({r.namespace}, {"holonomic" if r.holonomic else "differential"})'
            for r in robots))
        self._select(chosen)

    def _robots_of(self, values: list) -> List[PanelRobot]:
        """The driven bases of the simulator's world (its parameters ``values``: world,
        max_speed, max_turn), or none, said why."""
        if len(values) != 3 or values[0].type != ParameterType.PARAMETER_STRING:
            self._error(f'{self._sim} has no world parameter')
            return []
        max_speed = (values[1].double_value if values[1].type == ParameterType.PARAMETER_DOUBLE
                     else self._fallback[0])
        max_turn = (values[2].double_value if values[2].type == ParameterType.PARAMETER_DOUBLE
                    else self._fallback[1])
        try:
            world = load_world(resolve_resource(values[0].string_value))
        except (WorldConfigError, OSError, ValueError) as exc:
            self._error(f'cannot read the world of {self._sim}: {exc}')
            return []
        robots = robots_of_world(world, max_speed, max_turn)
        if not robots:
            self._error(f'the world {values[0].string_value} has no driven base')
        return robots

    def _select(self, robot: PanelRobot) -> None:
        """Drive ``robot`` from now on: the previous one is stopped first."""
        with self._lock:
            old = self.drive
            speed = old.speed_fraction if old else self._speed0
            report = old.report_turns if old else self._report_turns0
            if old is not None and self._out is not None:
                old.stop('another robot was chosen')
                self._publish(old.tick(time.monotonic()))
            self.drive = DeadMan(robot, self._deadman_timeout, speed, report)
            self._odom, self._path, self._jpeg = None, [], None
        if self._out is not None:
            self._out.destroy()
        if self._odom_sub is not None:
            self.destroy_subscription(self._odom_sub)
        self._drop_camera()
        self._out = TwistOut(self, robot.cmd_vel, self._stamped)
        self._odom_sub = self.create_subscription(Odometry, robot.odom, self._on_odom,
                                                  QoSProfile(depth=5))
        self.get_logger().info(f'driving {robot.name} on {robot.cmd_vel}')
        self._hello_due = True

    def _error(self, text: str) -> None:
        if text != self.last_error:
            self.last_error = text
            self.get_logger().error(text)
            self._server.broadcast('error', {'op': 'error', 'text': text})

    # --- commands -----------------------------------------------------------------------------
    def command(self, page: int, text: Any) -> Optional[str]:
        """A page's message; the reason it was refused, or None."""
        try:
            cmd = parse_command(text)
            with self._lock:
                drive = self.drive
                if drive is None:
                    raise PanelInputError('no robot yet: waiting for the simulator')
                now = time.monotonic()
                if cmd.op == 'hold':
                    drive.hold(cmd.motion, page, now)
                elif cmd.op == 'release':
                    drive.release(page)
                elif cmd.op == 'stop':
                    drive.stop('stop pressed')
                elif cmd.op == 'speed':
                    drive.set_speed(cmd.fraction)
                elif cmd.op == 'report_turns':
                    drive.set_report_turns(cmd.on)
                if cmd.op == 'select':
                    robot = next((r for r in self.robots if r.namespace == cmd.namespace),
                                 None)
                    if robot is None:
                        raise PanelInputError(f'no base in namespace {cmd.namespace[:100]!r}')
                    # (Made in the executor, where rclpy entities are made, at the next tick.)
                    self._wanted_robot = robot
                elif cmd.op in ('speed', 'report_turns'):
                    self._hello_due = True
            return None
        except PanelInputError as exc:
            line = self._refusal_log.text(page, time.monotonic(), f'page {page}: refused: {exc}')
            if line is not None:
                self.get_logger().warn(line)
            return str(exc)

    def page_gone(self, page: int) -> None:
        self._refusal_log.forget(page)
        with self._lock:
            if self.drive is not None:
                self.drive.gone(page)

    def _tick(self) -> None:
        with self._lock:
            wanted, self._wanted_robot = self._wanted_robot, None
            current = self.drive.robot if self.drive is not None else None
        if wanted is not None and wanted != current:
            self._select(wanted)
        with self._lock:
            if self.drive is None:
                return
            twist = self.drive.tick(time.monotonic())
            stops, self.drive.stops = self.drive.stops, []
        for why in stops:
            self.get_logger().info(f'stopped: {why}')
        self._publish(twist)

    def _publish(self, twist: Optional[Tuple[float, float, float]]) -> None:
        if twist is not None and self._out is not None:
            self._out.publish(*twist)

    # --- what the page shows ------------------------------------------------------------------
    def _on_odom(self, msg: Odometry) -> None:
        p, t = msg.pose.pose, msg.twist.twist
        odom = {'t': to_seconds(msg.header.stamp), 'x': p.position.x, 'y': p.position.y,
                'yaw': yaw_of(p.orientation), 'vx': t.linear.x, 'vy': t.linear.y,
                'wz': t.angular.z}
        with self._lock:
            self._odom = odom
            last = self._path[-1] if self._path else None
            if last is None or math.hypot(odom['x'] - last[0], odom['y'] - last[1]) >= PATH_STEP_M:
                self._path.append((round(odom['x'], 4), round(odom['y'], 4)))
                del self._path[:-PATH_POINTS]

    def _on_image(self, msg: CompressedImage) -> None:
        """The simulator's JPEG of the camera (image_transport's compressed transport), passed
        on as it is, at most ``camera_rate`` a second."""
        now = time.monotonic()
        if now - self._jpeg_at < self._camera_period or 'jpeg' not in msg.format:
            return
        self._jpeg_at = now
        with self._lock:
            self._jpeg = bytes(msg.data)

    def _on_state(self, msg: PipelineState) -> None:
        with self._lock:
            self._coordinator = {
                'status': msg.status, 'loader': msg.loader_state,
                'transport': msg.transport_state, 'elapsed': round(msg.elapsed, 2),
                'total': msg.total, 'identified': msg.identified, 'picked': msg.picked,
                'delivered': msg.delivered, 'missed': msg.missed, 'failed': msg.failed}

    def _on_event(self, msg: PipelineEvent) -> None:
        if msg.material_id < 0:
            return
        with self._lock:
            entry = self._materials.setdefault(msg.material_id, {'id': msg.material_id})
            entry.update({'color': msg.color or entry.get('color', ''), 'status': msg.kind,
                          'robot': msg.robot, 'detail': msg.detail,
                          't': round(to_seconds(msg.header.stamp), 2)})

    def _camera_wanted(self) -> None:
        """The camera is read only while a page is open (the simulator renders it for us)."""
        robot = self.drive.robot if self.drive else None
        if (self._server.pages and robot is not None and robot.camera
                and self._camera_sub is None):
            self._camera_sub = self.create_subscription(
                CompressedImage, f'{robot.camera}/compressed', self._on_image,
                qos_profile_sensor_data)
        elif not self._server.pages and self._camera_sub is not None:
            self._drop_camera()

    def _drop_camera(self) -> None:
        if self._camera_sub is not None:
            self.destroy_subscription(self._camera_sub)
            self._camera_sub = None

    def hello(self) -> Dict[str, Any]:
        with self._lock:
            drive = self.drive
            return {'op': 'hello', 'robots': [r.describe() for r in self.robots],
                    'namespace': drive.robot.namespace if drive else '',
                    'speed': drive.speed_fraction if drive else self._speed0,
                    'report_turns': drive.report_turns if drive else False,
                    'deadman_timeout': self._deadman_timeout, 'error': self.last_error}

    def _telemetry(self) -> None:
        self._camera_wanted()
        if not self._server.pages:
            return
        if self._hello_due:
            self._hello_due = False
            self._server.broadcast('hello', self.hello())
        with self._lock:
            drive = self.drive
            state = {'op': 'state', 'odom': self._odom, 'path': list(self._path),
                     'motion': drive.motion if drive else 'stop',
                     'command': list(drive.twist()) if drive and drive.motion != 'stop'
                     else [0.0, 0.0, 0.0],
                     'coordinator': self._coordinator,
                     'materials': sorted(self._materials.values(), key=lambda m: m['id'])}
            jpeg, self._jpeg = self._jpeg, None
        self._server.broadcast('state', state)
        if jpeg is not None:
            self._server.broadcast('frame', jpeg)

    def finish(self) -> str:
        with self._lock:
            if self.drive is not None:
                self.drive.stop('the panel stopped')
                twist = self.drive.tick(time.monotonic())
            else:
                twist = None
        if self.context.ok():
            self._publish(twist)
        self._server.close()
        return f'served {self.url}'


def _finish(node: ControlPanel) -> None:
    print(f'[control_panel] {node.finish()}', flush=True)


def main(args=None) -> int:
    return run_node(ControlPanel, 'control_panel', (ControlPanelError, PanelServerError),
                    on_exit=_finish,
                    args=args)


if __name__ == '__main__':
    sys.exit(main())

