"""ROS 2 node around SimRunner: the simulator's topics and services.

The node is an adapter. What it does lives elsewhere: the world and its physics in
``world.py``, advancing it and judging commands in ``runner.py`` (no ROS), how time advances
(real time, pause, lock-step ``~/step``) in ``stepping.py``, the trajectory actions in
``trajectory_action.py``, the messages in ``messages.py`` and the parameters in
``parameters.py``. Here: publishers and subscriptions, and the ``StepSink`` that publishes
what a step produces.
"""
from __future__ import annotations

import functools
import math
import re
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

from builtin_interfaces.msg import Time
from control_msgs.msg import JointTrajectoryControllerState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from sim_interfaces.msg import GripState
from std_msgs.msg import Bool, String
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from robot_description import with_frame_prefix
from ros_common.input_report import InputReport
from ros_common.log_limit import KeyedLimiter
from ros_common.node_main import run_node
from ros_common.params import declare_params
from ros_common.services import SERVICE_QOS
from ros_common.stamps import stamp_from_ns
from sim_bridge import messages
from sim_bridge.camera import ImageBuffer
from sim_bridge.entities import Entities
from sim_bridge.frames import WorldFrames
from sim_bridge.hold_watch import HoldWatch
from sim_bridge.joint_speed import BrakeBook
from sim_bridge.messages import topic
from sim_bridge.parameters import PARAMS, SimConfigError, check_params
from sim_bridge.runner import ZERO, DriveLimits, SimRunner, Twist3
from sim_bridge.sim_api import SimulationInterfaces
from sim_bridge.stepping import Stepping
from sim_bridge.trajectory_action import TrajectoryActions
from sim_bridge.world import SimWorld, WorldError
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world

# A reliable writer keeps only `depth` samples for a reader that falls behind: 100 lets a
# recorder starved for a moment (or a lock-step burst) still receive every message.
HISTORY = QoSProfile(depth=100)
# Latched, as robot_state_publisher and tf2's static broadcaster offer their topics.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABILITIES = {'reliable': ReliabilityPolicy.RELIABLE,
                 'best_effort': ReliabilityPolicy.BEST_EFFORT}
# Wall seconds between a quitting request's reply and the end of the node.
QUIT_DELAY_S = 1.0
# Numbers in a rejection's reason: two reasons that differ only in them are of one kind.
_NUMBERS = re.compile(r'-?\d[\d.e+-]*|nan|inf')


@dataclass
class _RobotIO:
    """One robot's publishers."""
    joints: Publisher
    frames: Tuple[str, str]                  # its odom and base_link frames
    odom: Optional[Publisher] = None
    cmd_out: Optional[Publisher] = None      # for a driven base
    suction: str = ''                        # its suction service's name, if it has one
    holding: Optional[Tuple[Publisher, Publisher]] = None
    states: Dict[str, Publisher] = field(default_factory=dict)    # per controller


@dataclass
class _CameraIO:
    """One camera's publishers, and the messages its frames are written into."""
    image: Publisher
    jpeg: Publisher
    info: Publisher
    image_msg: Image
    info_msg: CameraInfo
    buffer: ImageBuffer


class SimNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('sim_node', **kwargs)
        p = declare_params(self, PARAMS)
        check_params(p)
        world_path = resolve_resource(p['world'])
        seed = p['scenario_seed'] if p['scenario_seed'] >= 0 else None
        self._world = SimWorld(load_world(world_path), time_step=p['time_step'], gui=p['gui'],
                               scenario_seed=seed)
        if self._world.conveyor is not None and p['belt_speed'] >= 0.0:
            self._world.conveyor.speed = p['belt_speed']
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._runner = SimRunner(self._world, DriveLimits(
            p['max_speed'], p['max_turn'], p['cmd_vel_timeout'],
            p['linear.x.max_acceleration'] or None, p['angular.z.max_acceleration'] or None),
            p['state_publish_rate'], p['materials_publish_rate'], p['clock_publish_rate'])
        self._clock_pub = self.create_publisher(ClockMsg, '/clock', HISTORY)
        self._clock_msg = ClockMsg()
        self._robots = {name: self._robot_io(name, p['use_stamped_vel'])
                        for name in self._world.robots}
        self._jpeg_quality = p['jpeg_quality']
        self._cameras = [self._camera_io(cam, RELIABILITIES[p['camera_reliability']])
                         for cam in self._world.cameras]
        self._start_tf(p['publish_link_tf'])
        self._hold_watch = HoldWatch(self._world)
        # Rejected and clamped commands: a line a second per robot, topic and kind; and every
        # one counted per input on /diagnostics once a second (wall time) once there is one.
        self._rejections = KeyedLimiter(1.0)
        self._input_report = InputReport()
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # Joints braked back to their speed limits (joint_speed.py); latched: each robot's
        # joints driven past their limits since the start or the last reset (a trial's result
        # takes them).
        self._brakes = BrakeBook()
        self._brakes_pub = self.create_publisher(DiagnosticArray, '~/joint_limits', LATCHED)
        self.create_timer(1.0, self._publish_input_report,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._actions = TrajectoryActions(self, self._world, self._runner)
        self._materials_pub = (self.create_publisher(MarkerArray, '/cell/materials', HISTORY)
                               if self._world.source is not None else None)
        self.create_service(Trigger, '~/reset', self._on_reset, qos_profile=SERVICE_QOS)
        self._stepping = Stepping(
            self, self._runner, self, self._actions, synchronous=p['synchronous'],
            time_step=p['time_step'], real_time_factor=p['real_time_factor'],
            max_steps_per_tick=p['max_steps_per_tick'], step_chunk=p['step_chunk'],
            rtf_log_period=p['rtf_log_period'])
        # The standard simulator interfaces (sim_api.py); quitting through them ends the run.
        self.exit_request, self.exit_code = threading.Event(), 0
        self._entities = Entities(self._world, lambda: self._world.sim_time)
        self._sim_api = SimulationInterfaces(self, self._stepping, self._entities,
                                             self._reset_world, self._quit_soon,
                                             p['world'], lambda: self._world.sim_time_ns)
        self._runner.tick_clock(self)
        for name in self._world.robots:
            self.on_state(name, self._world.sim_time_ns)
        self.get_logger().info(
            f'world {world_path} with robots {sorted(self._world.robots)} and cameras '
            f'{[c.config.name for c in self._world.cameras]}; dt {p["time_step"]:.6f} s, '
            f'{self._stepping.describe()}; cmd_vel limits {self._limits_summary()}, '
            f'cmd_vel timeout {p["cmd_vel_timeout"]} s; trajectory controllers '
            f'{self._controllers_summary()}')

    # --- start-up -----------------------------------------------------------------------------
    def _robot_io(self, name: str, stamped_vel: bool) -> _RobotIO:
        robot = self._world.robots[name]
        ns, prefix = robot.config.namespace, robot.config.frame_prefix
        io = _RobotIO(self.create_publisher(JointState, topic(ns, 'joint_states'), HISTORY),
                      (prefix + 'odom', prefix + 'base_link'))
        if not robot.config.fixed_base:
            io.odom = self.create_publisher(Odometry, topic(ns, 'odom'), HISTORY)
        suction = robot.config.suction
        if name in self._world.suctions and suction is not None:
            service = topic(ns, suction.service)
            io.suction = suction.service
            self.create_service(SetBool, service, functools.partial(self._on_suction, name),
                                qos_profile=SERVICE_QOS)
            # The cup's vacuum switch: true while it holds a part; and the same, stamped.
            io.holding = (self.create_publisher(Bool, f'{service}/holding', HISTORY),
                          self.create_publisher(GripState, f'{service}/state', HISTORY))
        if name in self._runner.guards:
            # The command as applied (clamped, zeroed on bad input or by the timeout), when it
            # changes and stamped when it took effect: diff_drive_controller's cmd_vel_out.
            # Transient local: a checker that joins late still gets the first changes.
            io.cmd_out = self.create_publisher(
                TwistStamped, topic(ns, 'cmd_vel_out'),
                QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            self.create_subscription(TwistStamped if stamped_vel else Twist,
                                     topic(ns, 'cmd_vel'),
                                     functools.partial(self._on_cmd_vel, name), 10)
        for controller in robot.controllers:
            self.create_subscription(
                JointTrajectory, topic(ns, f'{controller}/joint_trajectory'),
                functools.partial(self._on_trajectory, name, controller), 10)
            io.states[controller] = self.create_publisher(
                JointTrajectoryControllerState, topic(ns, f'{controller}/controller_state'),
                HISTORY)
        return io

    def _camera_io(self, cam, reliability: ReliabilityPolicy) -> _CameraIO:
        c = cam.config
        ns = self._world.robots[c.robot].config.namespace if c.robot else ''
        # Reliable by default, keeping a second of frames: best-effort readers (the
        # sensor-data profile, as the vision node reads) match it too, and reliable ones (a
        # recorder, RViz's and rqt's defaults) get every frame after a stall of up to a second.
        qos = QoSProfile(depth=max(5, math.ceil(c.rate)), reliability=reliability)
        image = Image(height=c.height, width=c.width, encoding='rgb8', is_bigendian=0,
                      step=3 * c.width, data=bytes(3 * c.width * c.height))
        image.header.frame_id = c.frame_id
        return _CameraIO(
            self.create_publisher(Image, topic(ns, f'{c.name}/image_raw'), qos),
            # image_transport's compressed transport: JPEG, encoded only while subscribed.
            self.create_publisher(CompressedImage, topic(ns, f'{c.name}/image_raw/compressed'),
                                  qos),
            self.create_publisher(CameraInfo, topic(ns, f'{c.name}/camera_info'), qos),
            image, messages.camera_info(c, cam.intrinsics),
            # Frames are written into the message's own byte array (see ImageBuffer).
            ImageBuffer(c.width, c.height, image.data))

    def _start_tf(self, link_tf: bool) -> None:
        """TF (frames.py): moving frames on /tf at the state rate while someone listens; the
        rest once on /tf_static, latched. And each robot's URDF, its links named with its
        frame prefix, latched as robot_state_publisher offers it (what RViz and Foxglove draw
        the robot from)."""
        self._frames = WorldFrames(self._world)
        self._link_tf = link_tf
        self._tf_pub = self.create_publisher(TFMessage, '/tf', HISTORY)
        self._tf_static_pub = self.create_publisher(TFMessage, '/tf_static', LATCHED)
        static = self._frames.static()
        if not link_tf:
            # (robot_state_publisher publishes the fixed joints from the robot_description.)
            anchors = {f.anchor().child for f in self._frames.robots.values()}
            cameras = {c.config.frame_id for c in self._world.cameras if c.robot is None}
            static = [t for t in static if t.child in anchors | cameras]
        stamp = stamp_from_ns(self._world.sim_time_ns)
        self._tf_static_pub.publish(TFMessage(transforms=[messages.transform(t, stamp)
                                                          for t in static]))
        self._description_pubs = []
        for robot in self._world.robots.values():
            pub = self.create_publisher(String, topic(robot.config.namespace,
                                                      'robot_description'), LATCHED)
            pub.publish(String(data=with_frame_prefix(robot.urdf.read_text(),
                                                      robot.config.frame_prefix)))
            self._description_pubs.append(pub)

    def _limits_summary(self) -> str:
        return ', '.join(f'{name} {self._runner.shown(name, guard.limits)}'
                         for name, guard in self._runner.guards.items()) or 'none'

    def _controllers_summary(self) -> str:
        return ', '.join(f'{name}/{c}' for name, robot in self._world.robots.items()
                         for c in robot.controllers) or 'none'

    # --- StepSink: what a step produces -------------------------------------------------------
    def on_clock(self, time_ns: int) -> None:
        self._clock_msg.clock = stamp_from_ns(time_ns)
        self._clock_pub.publish(self._clock_msg)

    def on_trajectory_aborted(self, robot: str, controller: str, reason: str) -> None:
        self._actions.abort((robot, controller), reason)
        self._input_report.add(robot, f'{controller}/joint_trajectory', 'aborted', reason)
        text = self._rejections.text(
            (robot, controller, 'aborted'), time.monotonic(),
            f'{robot}/{controller}: trajectory aborted: {reason}; holding position')
        if text is not None:
            self.get_logger().error(text)

    def on_fault(self, robot: str, reason: str) -> None:
        for controller in self._world.robots[robot].controllers:
            self._actions.abort((robot, controller), reason)
        self.get_logger().error(
            f'{reason}: {robot} was stopped and put back at its start pose, at rest; it takes '
            'no commands or trajectories until ~/reset')
        if robot in self._runner.guards:
            self._publish_applied(robot, self._world.sim_time_ns, self._runner.applied(robot))

    def on_body_lost(self, name: str, what: str) -> None:
        self.get_logger().error(f'{name}: {what}')

    def on_joints_braked(self, robot: str, time_ns: int, braked) -> None:
        lines = self._brakes.add(robot, time_ns * 1e-9, braked)
        for b, line in zip([b for b in braked if b.driven_past], lines):
            text = self._rejections.text((robot, b.joint, 'driven'), time.monotonic(), line)
            if text is not None:
                self.get_logger().warning(text)
        if lines:
            self._publish_brakes()

    def _brake_statuses(self) -> list:
        out = []
        for robot in sorted(self._world.robots):
            driven, message, values = self._brakes.status(robot)
            out.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN if driven else DiagnosticStatus.OK,
                name=f'{self.get_name()}: {robot} joint speed limits', hardware_id=robot,
                message=message, values=[KeyValue(key=k, value=v) for k, v in values]))
        return out

    def _publish_brakes(self) -> None:
        msg = DiagnosticArray(status=self._brake_statuses())
        msg.header.stamp = stamp_from_ns(self._world.sim_time_ns)
        self._brakes_pub.publish(msg)

    def on_state(self, robot: str, time_ns: int) -> None:
        # A state nobody reads is not built or sent (as the cameras): each costs about a
        # millisecond in rclpy, and a lock-step trial sends about 20,000 of them. A reader that
        # joins gets the next one.
        stamp = stamp_from_ns(time_ns)
        sim_robot, io = self._world.robots[robot], self._robots[robot]
        if _wanted(self._tf_pub):
            moving = self._frames.moving(robot, links=self._link_tf)
            if moving:
                self._tf_pub.publish(TFMessage(transforms=[messages.transform(t, stamp)
                                                           for t in moving]))
        self._actions.on_state(robot, time_ns * 1e-9)
        for report in self._hold_watch.update(time_ns * 1e-9):
            # (One call site per severity: rclpy refuses a call site whose severity changes.)
            if report.blocked:
                self.get_logger().warning(report.text)
            else:
                self.get_logger().info(report.text)
        if _wanted(io.joints):
            io.joints.publish(messages.joint_state(sim_robot.joint_states(), stamp))
        if io.holding is not None:
            self._publish_suction(robot, io.holding, stamp)
        for name, group in sim_robot.controllers.items():
            if _wanted(io.states[name]):
                io.states[name].publish(messages.controller_state(group, stamp))
        if io.odom is not None and _wanted(io.odom):
            io.odom.publish(messages.odometry(sim_robot.base_state(), io.frames, stamp))

    def _publish_suction(self, robot: str, pubs: Tuple[Publisher, Publisher],
                         stamp: Time) -> None:
        suction = self._world.suctions[robot]
        holding = suction.held is not None
        bool_pub, state_pub = pubs
        if _wanted(bool_pub):
            bool_pub.publish(Bool(data=holding))
        if _wanted(state_pub):
            grip = GripState(armed=suction.armed, holding=holding)
            grip.header.stamp = stamp
            state_pub.publish(grip)

    def on_world_state(self, time_ns: int) -> None:
        if self._materials_pub is None or not _wanted(self._materials_pub):
            return
        world, source, conveyor = self._world, self._world.source, self._world.conveyor
        if source is None or conveyor is None:
            return
        held = {s.held.index for s in world.suctions.values() if s.held is not None}
        resting = set(conveyor.resting([m.body for m in world.materials]))
        stamp = stamp_from_ns(time_ns)
        msg = MarkerArray()
        for m in world.materials:
            pos, rot = source.pose(m)
            state = ('held' if m.index in held else
                     'on_belt' if m.body in resting else 'free')
            msg.markers.append(messages.material_marker(m, pos, rot, state, source.config,
                                                        stamp))
        self._materials_pub.publish(msg)

    def on_camera_due(self, index: int, time_ns: int, render) -> None:
        # Rendering dominates the cost of a step: only for image subscribers.
        stamp = stamp_from_ns(time_ns)
        cam = self._cameras[index]
        raw, jpeg = _wanted(cam.image), _wanted(cam.jpeg)
        if raw or jpeg:
            rgba = render()
            if raw:
                cam.buffer.fill_from_rgba(rgba)
                cam.image_msg.header.stamp = stamp
                cam.image.publish(cam.image_msg)
            compressed = self._jpeg(cam, rgba, stamp) if jpeg else None
            if compressed is not None:
                cam.jpeg.publish(compressed)
        elif not _wanted(cam.info):
            return
        cam.info_msg.header.stamp = stamp
        cam.info.publish(cam.info_msg)

    def _jpeg(self, cam: _CameraIO, rgba, stamp: Time) -> Optional[CompressedImage]:
        import cv2  # (only for a compressed-image subscriber)
        ok, data = cv2.imencode('.jpg', cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, self._jpeg_quality])
        if not ok:
            self.get_logger().error('a camera frame could not be encoded as JPEG',
                                    throttle_duration_sec=5.0)
            return None
        msg = CompressedImage(format='rgb8; jpeg compressed bgr8', data=data.tobytes())
        msg.header.stamp = stamp
        msg.header.frame_id = cam.image_msg.header.frame_id
        return msg

    def on_command_timeout(self, robot: str) -> None:
        self.get_logger().info(f'{robot}: no cmd_vel for {self._runner.guards[robot].timeout} s;'
                               ' stopping', throttle_duration_sec=5.0)

    def on_command_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        self._publish_applied(robot, time_ns, command)

    def _publish_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        io = self._robots[robot]
        if io.cmd_out is not None:
            io.cmd_out.publish(messages.applied_twist(command, io.frames[1],
                                                      stamp_from_ns(time_ns)))

    # --- subscriptions and services -----------------------------------------------------------
    def _on_cmd_vel(self, robot: str, msg) -> None:
        self._stepping.command_arrived()
        verdict = self._runner.judge_twist(robot, messages.twist_values(msg),
                                           messages.twist_stamp(msg))
        for kind, text in verdict.notes:
            self._warn((robot, 'cmd_vel', kind, _NUMBERS.sub('#', text)), kind,
                       f'{robot}/cmd_vel {text}')

    def _warn(self, key: tuple, kind: str, message: str) -> None:
        """A warning per robot, topic and kind, at most one a second, counting those held;
        every one counted for /diagnostics under ``kind``."""
        self._input_report.add(key[0], key[1], kind, message)
        text = self._rejections.text(key, time.monotonic(), message)
        if text is not None:
            self.get_logger().warn(text)

    def _publish_input_report(self) -> None:
        msg = DiagnosticArray(status=self._brake_statuses())
        msg.header.stamp = stamp_from_ns(self._world.sim_time_ns)
        for status in self._input_report.statuses():
            msg.status.append(DiagnosticStatus(
                level=bytes([status.level]), name=f'{self.get_name()}: {status.name}',
                hardware_id=status.hardware_id, message=status.message,
                values=[KeyValue(key=k, value=v) for k, v in status.values]))
        self._diagnostics_pub.publish(msg)

    def _on_trajectory(self, robot: str, controller: str, msg: JointTrajectory) -> None:
        self._stepping.command_arrived()
        result = self._runner.set_trajectory(robot, controller,
                                             messages.trajectory_request(msg))
        where = f'{robot}/{controller}'
        if result.accepted:
            self._actions.preempt((robot, controller), 'preempted by a trajectory on the topic')
            self.get_logger().info(f'{where}: following a trajectory of {len(msg.points)} '
                                   f'points for {list(msg.joint_names)}')
            return
        self._input_report.add(robot, f'{controller}/joint_trajectory', 'rejected',
                               result.reason)
        text = self._rejections.text(
            (robot, controller, _NUMBERS.sub('#', result.reason)), time.monotonic(),
            f'{where}: trajectory rejected: {result.reason}; holding position')
        if text is not None:
            self.get_logger().error(text)

    def _on_suction(self, robot: str, request, response):
        suction = self._world.suctions[robot]
        source = self._world.source
        response.success, response.message = (suction.switch_on(source) if request.data
                                               else suction.release(source))
        text = (f'{robot}/{self._robots[robot].suction} {"on" if request.data else "off"}: '
                f'{response.message}')
        # (rclpy forbids two severities from one logging call site.)
        if response.success:
            self.get_logger().info(text)
        else:
            self.get_logger().warn(text)
        return response

    def _on_set_parameters(self, params):
        for param in params:
            if param.name == 'belt_speed':
                why = self._set_belt_speed(float(param.value))
                if why:
                    return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)

    def _set_belt_speed(self, speed: float) -> str:
        """Why the belt cannot run at ``speed`` [m/s] (-1: the world file's), or '' once set."""
        conveyor = self._world.conveyor
        if conveyor is None:
            return 'this world has no conveyor'
        if speed == -1.0:
            speed = conveyor.config.belt_speed
        elif not speed >= 0.0:
            # (The belt runs one way: a negative speed would have been "set" and ignored.)
            return (f'belt_speed {speed} m/s: the belt runs forward only (>= 0, or -1 for the '
                    "world file's)")
        conveyor.speed = speed
        self.get_logger().info(f'belt speed {speed:.3f} m/s')
        return ''

    def _on_reset(self, _request, response):
        response.success, response.message = True, self._reset_world()
        return response

    def _reset_world(self) -> str:
        """Robots back at their start poses, the materials' scenario again, faults cleared
        (simulated time runs on); what was done. Step requests being served end first."""
        ended = self._stepping.end_steps('a reset')
        aborted = self._actions.abort_all(
            'the simulation was reset: the arm is back at its start pose', hold=False)
        faults = list(self._runner.faults)
        self._runner.reset()
        self._brakes.clear()
        self._publish_brakes()
        self._hold_watch = HoldWatch(self._world)     # (simulated time starts again)
        now = self._world.sim_time_ns
        for name in self._world.robots:
            if name in self._runner.guards:
                self._publish_applied(name, now, ZERO)
            self.on_state(name, now)
        self.get_logger().info('world reset' + (f'; goals aborted: {", ".join(aborted)}'
                                                if aborted else ''))
        return 'robots returned to their start poses' + (
            f' (faults cleared: {", ".join(faults)})' if faults else '') + (
            f' (goals aborted: {", ".join(aborted)})' if aborted else '') + (
            f'; {ended}' if ended else '')

    def _quit_soon(self) -> None:
        """End the run a second after the reply that asked for it (the reply must reach its
        client before the node is gone: on a loaded machine it was lost)."""
        def quit_now() -> None:
            timer.cancel()
            self.exit_request.set()
        timer = self.create_timer(QUIT_DELAY_S, quit_now,
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))

    def destroy_node(self) -> None:
        # Leave no robot driving on a stale command.
        self._runner.stop_all()
        self._entities.spawner.close()
        self._world.close()
        super().destroy_node()


def _wanted(publisher: Publisher) -> bool:
    """Someone reads this topic now."""
    return publisher.get_subscription_count() > 0


def main(args=None) -> int:
    return run_node(SimNode, 'sim_node',
                    (SimConfigError, WorldConfigError, WorldError, FileNotFoundError), args=args)


if __name__ == '__main__':
    sys.exit(main())
