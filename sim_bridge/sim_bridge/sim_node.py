"""ROS 2 node around SimRunner: parameters, topics, services and real-time pacing."""
from __future__ import annotations

import collections
import functools
import math
import re
import sys
import time
from dataclasses import dataclass
from typing import Deque, Dict, List, Optional

from builtin_interfaces.msg import Time
from control_msgs.msg import JointTrajectoryControllerState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from sim_interfaces.msg import GripState
from sim_interfaces.srv import StepSimulation
from std_msgs.msg import Bool, String
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from controllers.cmd_guard import non_finite_fields
from controllers.joint_trajectory import TrajectoryPoint, TrajectoryRequest
from controllers.lockstep import CommandBarrier
from controllers.transforms import matrix_to_quaternion
from robot_description import with_frame_prefix
from ros_common.deferred_reply import DeferredReplies
from ros_common.input_report import InputReport
from ros_common.log_limit import KeyedLimiter
from ros_common.node_main import run_node
from ros_common.params import float_range
from ros_common.services import SERVICE_QOS
from ros_common.stamps import stamp_from_ns, to_seconds
from sim_bridge.camera import ImageBuffer
from sim_bridge.frames import FrameTransform, WorldFrames
from sim_bridge.hold_watch import HoldWatch
from sim_bridge.pacing import Pacer, RtfMeter
from sim_bridge.runner import DriveLimits, SimRunner
from sim_bridge.trajectory_action import TrajectoryActions, fill_points
from sim_bridge.world import SimWorld, WorldError
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world

DEFAULT_WORLD = 'package://world_description/worlds/mini_robot.yaml'
MAX_STEPS_PER_REQUEST = 100_000
# Ground truth: tiny but non-zero covariance (zero often reads as "unknown").
GROUND_TRUTH_COVARIANCE = [1e-9 if i % 7 == 0 else 0.0 for i in range(36)]


class SimConfigError(ValueError):
    """A parameter combination the simulator cannot run with."""



class SimNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('sim_node', **kwargs)
        ro = ParameterDescriptor
        self.declare_parameter('world', DEFAULT_WORLD, ro(
            description='World YAML: a path or package://<pkg>/<path>', read_only=True))
        self.declare_parameter('gui', False, ro(
            description='Open the PyBullet GUI (needs a display)', read_only=True))
        self.declare_parameter('time_step', 1.0 / 240.0, float_range(
            'Fixed physics step [s]', 1e-4, 0.05))
        self.declare_parameter('real_time_factor', 1.0, float_range(
            'Pacing: simulated seconds per wall second; 0 runs as fast as possible', 0.0, 100.0))
        self.declare_parameter('synchronous', False, ro(
            description='Lock-step: physics advances only on ~/step requests', read_only=True))
        self.declare_parameter('state_publish_rate', 100.0, float_range(
            'Rate of joint_states and odom [Hz of simulated time]', 0.1, 10000.0))
        self.declare_parameter('clock_publish_rate', 0.0, float_range(
            'Rate of /clock [Hz of simulated time]; 0: after every physics step. Lock-step '
            'also publishes it at the end of every ~/step. Each message costs every node '
            'with use_sim_time about a millisecond of CPU in rclpy; a node that plans ahead '
            'in real time needs a fresh clock', 0.0, 10000.0))
        self.declare_parameter('max_speed', 0.2, float_range(
            'Linear speed limit (each of x, y) of bases whose world entry sets none [m/s]',
            1e-3, 10.0))
        self.declare_parameter('max_turn', 0.2, float_range(
            'Turn rate limit of bases whose world entry sets none [rad/s]', 1e-3, 20.0))
        # diff_drive_controller's names; the world file's max_accel and max_turn_accel win.
        self.declare_parameter('linear.x.max_acceleration', 0.0, float_range(
            'Acceleration limit of the applied command (each of linear x and y) of bases whose '
            'world entry sets none [m/s^2]; 0: no limit', 0.0, 100.0))
        self.declare_parameter('angular.z.max_acceleration', 0.0, float_range(
            'Angular acceleration limit of the applied command of bases whose world entry sets '
            'none [rad/s^2]; 0: no limit', 0.0, 200.0))
        self.declare_parameter('cmd_vel_timeout', 0.5, float_range(
            'Stop a base when its last cmd_vel is older than this [s of simulated time]',
            1e-3, 60.0))
        self.declare_parameter('use_stamped_vel', False, ro(
            description='Take geometry_msgs/TwistStamped on cmd_vel instead of Twist',
            read_only=True))
        self.declare_parameter('rtf_log_period', 10.0, float_range(
            'Log the achieved real-time factor every this many wall seconds; 0 disables',
            0.0, 3600.0))
        # Behind schedule, the steps of a burst take no commands: 64 (0.27 s) left the
        # youBot turning on a stale cmd_vel and into the pool's wall (real time, loaded).
        self.declare_parameter('max_steps_per_tick', 8, ParameterDescriptor(
            description='Most physics steps run between two rounds of callbacks',
            read_only=True, integer_range=[IntegerRange(from_value=1, to_value=10000, step=1)]))

        self.declare_parameter('step_chunk', 240, ParameterDescriptor(
            description='Lock-step: a ~/step request of more steps is run this many at a time, '
                        'the node serving its other callbacks (commands, services) between '
                        'chunks, and answered after the last',
            read_only=True, integer_range=[IntegerRange(from_value=1, to_value=100000, step=1)]))

        self.declare_parameter('belt_speed', -1.0, float_range(
            'Conveyor belt speed [m/s]; -1 keeps the world file\'s; settable while running',
            -1.0, 2.0, read_only=False))
        self.declare_parameter('scenario_seed', -1, ParameterDescriptor(
            description='Seed of the materials\' order and spacing; -1 keeps the world file\'s',
            read_only=True,
            integer_range=[IntegerRange(from_value=-1, to_value=2**31 - 1, step=1)]))
        self.declare_parameter('materials_publish_rate', 10.0, float_range(
            'Rate of the materials\' ground truth on /cell/materials [Hz of simulated time]',
            0.1, 1000.0))

        self.declare_parameter('publish_link_tf', True, ro(
            description='Publish the robots\' link transforms on /tf and /tf_static (off: '
                        'robot_state_publisher does it from joint_states and '
                        'robot_description); odom -> base_link and the world\'s anchors are '
                        'published either way', read_only=True))

        self.declare_parameter('camera_reliability', 'reliable', ro(
            description='QoS reliability of camera images and camera_info: reliable (the '
                        'system default, which RViz and rqt ask for; best-effort readers match '
                        'it too) or best_effort', read_only=True))
        self.declare_parameter('jpeg_quality', 90, ParameterDescriptor(
            description='JPEG quality of <camera>/image_raw/compressed',
            read_only=True, integer_range=[IntegerRange(from_value=1, to_value=100, step=1)]))

        p = {name: self.get_parameter(name).value for name in (
            'world', 'gui', 'time_step', 'real_time_factor', 'synchronous', 'state_publish_rate',
            'clock_publish_rate', 'max_speed', 'max_turn', 'linear.x.max_acceleration',
            'angular.z.max_acceleration', 'cmd_vel_timeout', 'use_stamped_vel',
            'rtf_log_period', 'max_steps_per_tick', 'step_chunk', 'belt_speed', 'scenario_seed',
            'materials_publish_rate', 'publish_link_tf', 'camera_reliability', 'jpeg_quality')}
        reliabilities = {'reliable': ReliabilityPolicy.RELIABLE,
                         'best_effort': ReliabilityPolicy.BEST_EFFORT}
        if p['camera_reliability'] not in reliabilities:
            raise SimConfigError(f'camera_reliability must be reliable or best_effort, got '
                                 f'"{p["camera_reliability"]}"')
        self._jpeg_quality = p['jpeg_quality']
        if p['state_publish_rate'] * p['time_step'] > 1.0 + 1e-9:
            raise SimConfigError(
                f'state_publish_rate {p["state_publish_rate"]} Hz exceeds the physics rate '
                f'{1.0 / p["time_step"]:.1f} Hz (1/time_step)')
        world_path = resolve_resource(p['world'])
        config = load_world(world_path)
        seed = p['scenario_seed'] if p['scenario_seed'] >= 0 else None
        self._world = SimWorld(config, time_step=p['time_step'], gui=p['gui'],
                               scenario_seed=seed)
        if self._world.conveyor is not None and p['belt_speed'] >= 0.0:
            self._world.conveyor.speed = p['belt_speed']
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._runner = SimRunner(self._world, DriveLimits(
            p['max_speed'], p['max_turn'], p['cmd_vel_timeout'],
            p['linear.x.max_acceleration'] or None, p['angular.z.max_acceleration'] or None),
            p['state_publish_rate'],
            p['materials_publish_rate'], p['clock_publish_rate'])
        self._synchronous = p['synchronous']
        self._paused = False
        self._pacer = Pacer(p['time_step'], p['real_time_factor'], p['max_steps_per_tick'])
        self._rtf = RtfMeter()
        self._rtf_log_period = p['rtf_log_period']
        self._last_rtf_log = time.monotonic()

        reliable = QoSProfile(depth=10)
        # A reliable writer keeps only `depth` samples for a reader that falls behind: 100 lets a
        # recorder starved for a moment (or a lock-step burst) still receive every message.
        history = QoSProfile(depth=100)
        self._clock_pub = self.create_publisher(ClockMsg, '/clock', history)
        self._clock_msg = ClockMsg()
        self._joint_pubs, self._odom_pubs, self._odom_frames = {}, {}, {}
        self._state_pubs = {}
        self._holding_pubs = {}
        self._suction_services: Dict[str, str] = {}      # robot: its suction service's name
        self._cmd_out_pubs = {}
        for name, robot in self._world.robots.items():
            ns = robot.config.namespace
            prefix = robot.config.frame_prefix
            self._joint_pubs[name] = self.create_publisher(
                JointState, _topic(ns, 'joint_states'), history)
            if not robot.config.fixed_base:
                self._odom_pubs[name] = self.create_publisher(Odometry, _topic(ns, 'odom'),
                                                              history)
            suction = robot.config.suction
            if name in self._world.suctions and suction is not None:
                service = _topic(ns, suction.service)
                self._suction_services[name] = suction.service
                self.create_service(SetBool, service, functools.partial(self._on_suction, name),
                                    qos_profile=SERVICE_QOS)
                # The cup's vacuum switch: true while it holds a part; and the same, stamped.
                self._holding_pubs[name] = (
                    self.create_publisher(Bool, f'{service}/holding', history),
                    self.create_publisher(GripState, f'{service}/state', history))
            self._odom_frames[name] = (prefix + 'odom', prefix + 'base_link')
            if name in self._runner.guards:
                # The command as applied (clamped, zeroed on bad input or by the timeout), when
                # it changes and stamped when it took effect: diff_drive_controller's
                # cmd_vel_out. What a base really did can be judged against it. Transient local:
                # a checker that joins late still gets the first changes.
                self._cmd_out_pubs[name] = self.create_publisher(
                    TwistStamped, _topic(ns, 'cmd_vel_out'),
                    QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
                msg_type = TwistStamped if p['use_stamped_vel'] else Twist
                self.create_subscription(msg_type, _topic(ns, 'cmd_vel'),
                                         functools.partial(self._on_cmd_vel, name), reliable)
            for controller in robot.controllers:
                self.create_subscription(
                    JointTrajectory, _topic(ns, f'{controller}/joint_trajectory'),
                    functools.partial(self._on_trajectory, name, controller), reliable)
                self._state_pubs[(name, controller)] = self.create_publisher(
                    JointTrajectoryControllerState, _topic(ns, f'{controller}/controller_state'),
                    history)
        self._image_pubs, self._info_pubs, self._jpeg_pubs = [], [], []
        self._image_msgs: List[Image] = []
        self._info_msgs: List[CameraInfo] = []
        self._buffers: List[ImageBuffer] = []
        for cam in self._world.cameras:
            c = cam.config
            ns = self._world.robots[c.robot].config.namespace if c.robot else ''
            # Reliable, keeping a second of frames: best-effort readers (the sensor-data
            # profile, as the vision node reads) match it too, and reliable ones (a recorder,
            # RViz's and rqt's defaults) get every frame after a stall of up to a second.
            # Best-effort frames were lost under load (a recorder starved for 0.35 s).
            camera_qos = QoSProfile(depth=max(5, math.ceil(c.rate)),
                                    reliability=reliabilities[p['camera_reliability']])
            self._image_pubs.append(self.create_publisher(
                Image, _topic(ns, f'{c.name}/image_raw'), camera_qos))
            # image_transport's compressed transport: JPEG, encoded only while subscribed.
            self._jpeg_pubs.append(self.create_publisher(
                CompressedImage, _topic(ns, f'{c.name}/image_raw/compressed'), camera_qos))
            self._info_pubs.append(self.create_publisher(
                CameraInfo, _topic(ns, f'{c.name}/camera_info'), camera_qos))
            image = Image(height=c.height, width=c.width, encoding='rgb8', is_bigendian=0,
                          step=3 * c.width, data=bytes(3 * c.width * c.height))
            # Frames are written into the message's own byte array (see ImageBuffer).
            self._buffers.append(ImageBuffer(c.width, c.height, image.data))
            self._image_msgs.append(image)
            self._image_msgs[-1].header.frame_id = c.frame_id
            k = cam.intrinsics
            self._info_msgs.append(CameraInfo(
                height=c.height, width=c.width, distortion_model='plumb_bob',
                d=[0.0] * 5, k=list(k.k), r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p=list(k.p)))
            self._info_msgs[-1].header.frame_id = c.frame_id

        # TF (frames.py): moving frames on /tf at the state rate while someone listens; the
        # rest once on /tf_static, latched (transient local, as tf2's static broadcaster).
        self._frames = WorldFrames(self._world)
        self._link_tf = p['publish_link_tf']
        self._tf_pub = self.create_publisher(TFMessage, '/tf', history)
        self._tf_static_pub = self.create_publisher(
            TFMessage, '/tf_static', QoSProfile(
                depth=1, reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._publish_static_tf()
        # Each robot's URDF, its links named with its frame prefix (the frames of /tf), latched
        # as robot_state_publisher offers it: what RViz and Foxglove draw the robot from.
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._description_pubs = []
        for robot in self._world.robots.values():
            pub = self.create_publisher(String, _topic(robot.config.namespace,
                                                       'robot_description'), latched)
            pub.publish(String(data=with_frame_prefix(robot.urdf.read_text(),
                                                      robot.config.frame_prefix)))
            self._description_pubs.append(pub)

        self._hold_watch = HoldWatch(self._world)
        # Rejected and clamped commands: a line a second per robot, topic and kind.
        self._rejections = KeyedLimiter(1.0)
        # The senders' side of it: every rejection and clamp, counted per input, on
        # /diagnostics once a second (wall time) once there has been one.
        self._input_report = InputReport()
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(1.0, self._publish_input_report,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._actions = TrajectoryActions(
            self, self._world, self._runner, _topic, lambda msg: trajectory_request(msg),
            lambda: stamp_from_ns(self._world.sim_time_ns))

        self._materials_pub = None
        if self._world.source is not None:
            self._materials_pub = self.create_publisher(MarkerArray, '/cell/materials', history)
        self.create_service(Trigger, '~/reset', self._on_reset, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/pause', self._on_pause, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/resume', self._on_resume, qos_profile=SERVICE_QOS)
        # A step runs once the commands announced with it are in (lockstep.py); until then it
        # is answered at once with commands_pending, and asked again.
        self._barrier = CommandBarrier()
        step = self.create_service(StepSimulation, '~/step', self._on_step,
                                   qos_profile=SERVICE_QOS)
        # A request of more than step_chunk steps (or one behind it) is served a chunk at a
        # time from a timer, the node's other callbacks in between, and answered after its
        # last chunk: 100000 steps used to leave the node deaf for 40 s.
        self._step_replies = DeferredReplies(step)
        self._step_jobs: Deque[_StepJob] = collections.deque()
        self._step_chunk = p['step_chunk']
        self._chunk_timer = self.create_timer(0.001, self._on_step_chunk, clock=Clock(
            clock_type=ClockType.STEADY_TIME))
        self._chunk_timer.cancel()
        # The simulator is the time source: it paces itself on the steady wall clock.
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        rtf = p['real_time_factor']
        period = 0.0 if rtf == 0.0 else p['time_step'] / rtf
        self._timer = self.create_timer(period, self._on_tick, clock=self._steady)
        if self._synchronous:
            # Lock-step steps only on request: a timer firing at the physics rate for nothing
            # woke the executor 240 times a second (about a tenth of the node's CPU in a trial).
            self._timer.cancel()
        self._runner.tick_clock(self)
        for name in self._world.robots:
            self.on_state(name, self._world.sim_time_ns)

        self.get_logger().info(
            f'world {world_path} with robots {sorted(self._world.robots)} and cameras '
            f'{[c.config.name for c in self._world.cameras]}; dt {p["time_step"]:.6f} s, '
            + ('lock-step (synchronous)' if self._synchronous else
               'as fast as possible' if rtf == 0.0 else f'real-time factor {rtf:g}')
            + f'; cmd_vel limits {self._limits_summary()}, '
            f'cmd_vel timeout {p["cmd_vel_timeout"]} s; trajectory controllers '
            f'{self._controllers_summary()}')

    def _limits_summary(self) -> str:
        return ', '.join(f'{name} {_fmt(guard.limits)}'
                         for name, guard in self._runner.guards.items()) or 'none'

    def _controllers_summary(self) -> str:
        return ', '.join(f'{name}/{c}' for name, robot in self._world.robots.items()
                         for c in robot.controllers) or 'none'

    # --- stepping -------------------------------------------------------------------------
    def _on_tick(self) -> None:
        if self._synchronous or self._paused:
            return
        wall = time.monotonic()
        if self._pacer.as_fast_as_possible:
            # Step for about 2 ms, then let the executor serve callbacks.
            deadline = wall + 0.002
            steps = 0
            while steps < self._pacer.max_burst and time.monotonic() < deadline:
                self._runner.advance(1, self)
                steps += 1
        else:
            steps = self._pacer.steps_due(wall)
            self._runner.advance(steps, self)
            self._pacer.record(steps)
        if steps:
            self._note_progress()

    def _note_progress(self) -> None:
        wall = time.monotonic()
        self._rtf.add(wall, self._world.sim_time)
        if self._rtf_log_period > 0.0 and wall - self._last_rtf_log >= self._rtf_log_period:
            self._last_rtf_log = wall
            rtf = self._rtf.value()
            if rtf is not None:
                self.get_logger().info(f'real-time factor {rtf:.2f} '
                                       f'(sim time {self._world.sim_time:.1f} s)')

    # --- StepSink: what a step produces -----------------------------------------------------
    def on_clock(self, time_ns: int) -> None:
        self._publish_clock(time_ns)

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
        if robot in self._cmd_out_pubs:
            self._publish_applied(robot, self._world.sim_time_ns)

    def on_state(self, robot: str, time_ns: int) -> None:
        # A state nobody reads is not built or sent (as the cameras): each costs about a
        # millisecond in rclpy, and a lock-step trial sends about 20,000 of them. A reader that
        # joins gets the next one.
        stamp = stamp_from_ns(time_ns)
        sim_robot = self._world.robots[robot]
        if _wanted(self._tf_pub):
            self._publish_tf(robot, stamp)
        self._actions.on_state(robot, time_ns * 1e-9)
        for report in self._hold_watch.update(time_ns * 1e-9):
            # (One call site per severity: rclpy refuses a call site whose severity changes,
            # and a held arm freed again after a warning took the simulator down.)
            if report.blocked:
                self.get_logger().warning(report.text)
            else:
                self.get_logger().info(report.text)
        if _wanted(self._joint_pubs[robot]):
            js = sim_robot.joint_states()
            msg = JointState(name=js.names, position=js.positions, velocity=js.velocities,
                             effort=js.efforts)
            msg.header.stamp = stamp
            self._joint_pubs[robot].publish(msg)
        if robot in self._holding_pubs:
            suction = self._world.suctions[robot]
            holding = suction.held is not None
            bool_pub, state_pub = self._holding_pubs[robot]
            if _wanted(bool_pub):
                bool_pub.publish(Bool(data=holding))
            if _wanted(state_pub):
                grip = GripState(armed=suction.armed, holding=holding)
                grip.header.stamp = stamp
                state_pub.publish(grip)
        for name, group in sim_robot.controllers.items():
            if _wanted(self._state_pubs[(robot, name)]):
                self._state_pubs[(robot, name)].publish(
                    _controller_state(group, stamp))
        if robot not in self._odom_pubs or not _wanted(self._odom_pubs[robot]):
            return
        base = sim_robot.base_state()
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id, odom.child_frame_id = self._odom_frames[robot]
        pose, twist = odom.pose.pose, odom.twist.twist
        pose.position.x, pose.position.y, pose.position.z = base.position
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = base.orientation
        twist.linear.x, twist.linear.y, twist.linear.z = (float(v) for v in base.linear)
        twist.angular.x, twist.angular.y, twist.angular.z = (float(v) for v in base.angular)
        odom.pose.covariance = GROUND_TRUTH_COVARIANCE
        odom.twist.covariance = GROUND_TRUTH_COVARIANCE
        self._odom_pubs[robot].publish(odom)

    def _publish_static_tf(self) -> None:
        static = self._frames.static()
        if not self._link_tf:
            # (robot_state_publisher publishes the fixed joints from the robot_description.)
            anchors = {f.anchor().child for f in self._frames.robots.values()}
            cameras = {c.config.frame_id for c in self._world.cameras if c.robot is None}
            static = [t for t in static if t.child in anchors | cameras]
        stamp = stamp_from_ns(self._world.sim_time_ns)
        self._tf_static_pub.publish(TFMessage(transforms=[_transform(t, stamp)
                                                          for t in static]))

    def _publish_tf(self, robot: str, stamp: Time) -> None:
        moving = self._frames.moving(robot, links=self._link_tf)
        if moving:
            self._tf_pub.publish(TFMessage(transforms=[_transform(t, stamp) for t in moving]))

    def on_world_state(self, time_ns: int) -> None:
        if self._materials_pub is None or not _wanted(self._materials_pub):
            return
        world, source, conveyor = self._world, self._world.source, self._world.conveyor
        if source is None or conveyor is None:
            return
        held = {s.held.index for s in world.suctions.values() if s.held is not None}
        resting = set(conveyor.resting([m.body for m in world.materials]))
        msg = MarkerArray()
        for m in world.materials:
            pos, rot = source.pose(m)
            state = ('held' if m.index in held else
                     'on_belt' if m.body in resting else 'free')
            msg.markers.append(_material_marker(m, pos, rot, state, source.config,
                                                stamp_from_ns(time_ns)))
        self._materials_pub.publish(msg)

    def on_camera_due(self, index: int, time_ns: int, render) -> None:
        # Rendering dominates the cost of a step: only for image subscribers.
        stamp = stamp_from_ns(time_ns)
        raw = self._image_pubs[index].get_subscription_count() > 0
        jpeg = self._jpeg_pubs[index].get_subscription_count() > 0
        if raw or jpeg:
            rgba = render()
            if raw:
                image = self._image_msgs[index]
                self._buffers[index].fill_from_rgba(rgba)
                image.header.stamp = stamp
                self._image_pubs[index].publish(image)
            compressed = self._jpeg(index, rgba, stamp) if jpeg else None
            if compressed is not None:
                self._jpeg_pubs[index].publish(compressed)
        elif self._info_pubs[index].get_subscription_count() == 0:
            return
        info = self._info_msgs[index]
        info.header.stamp = stamp
        self._info_pubs[index].publish(info)

    def _jpeg(self, index: int, rgba, stamp: Time) -> Optional[CompressedImage]:
        import cv2  # (only for a compressed-image subscriber)
        ok, data = cv2.imencode('.jpg', cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, self._jpeg_quality])
        if not ok:
            self.get_logger().error('a camera frame could not be encoded as JPEG',
                                    throttle_duration_sec=5.0)
            return None
        msg = CompressedImage(format='rgb8; jpeg compressed bgr8', data=data.tobytes())
        msg.header.stamp = stamp
        msg.header.frame_id = self._image_msgs[index].header.frame_id
        return msg

    def on_command_timeout(self, robot: str) -> None:
        self.get_logger().info(f'{robot}: no cmd_vel for {self._runner.guards[robot].timeout} s;'
                               ' stopping', throttle_duration_sec=5.0)

    def on_command_applied(self, robot: str, time_ns: int) -> None:
        self._publish_applied(robot, time_ns)

    def _publish_applied(self, robot: str, time_ns: int) -> None:
        command = self._runner.applied(robot)
        vx, vy, wz = command if len(command) == 3 else (command[0], 0.0, command[1])
        msg = TwistStamped()
        msg.header.stamp = stamp_from_ns(time_ns)
        msg.header.frame_id = self._odom_frames[robot][1]
        msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z = vx, vy, wz
        self._cmd_out_pubs[robot].publish(msg)

    def _publish_clock(self, time_ns: int) -> None:
        self._clock_msg.clock = stamp_from_ns(time_ns)
        self._clock_pub.publish(self._clock_msg)

    # --- subscriptions and services --------------------------------------------------------
    def _on_cmd_vel(self, robot: str, msg) -> None:
        self._command_arrived()
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        broken = non_finite_fields((twist.linear.x, twist.linear.y, twist.linear.z,
                                    twist.angular.x, twist.angular.y, twist.angular.z))
        if broken:
            self._runner.reject(robot)
            self._warn((robot, 'cmd_vel', _NUMBERS.sub('#', broken)),
                       f'{robot}/cmd_vel rejected: non-finite {broken}; stopping', 'non-finite')
            return
        if isinstance(msg, TwistStamped) and (msg.header.stamp.sec or msg.header.stamp.nanosec):
            # Judged by its stamp, as diff_drive_controller does (an unset stamp counts as
            # now): one older than cmd_vel_timeout, or as far ahead, is not a command to act
            # on now (stamps of -5 s and 2**31 s used to be applied as fresh).
            stamp, now = to_seconds(msg.header.stamp), self._world.sim_time
            timeout = self._runner.guards[robot].timeout
            if abs(now - stamp) > timeout:
                self._runner.reject(robot)
                self._warn((robot, 'cmd_vel', 'old stamp' if stamp < now else 'future stamp'), (
                    f'{robot}/cmd_vel rejected: stamped {stamp:.3f} s, the simulator\'s clock '
                    f'reads {now:.3f} s (beyond cmd_vel_timeout {timeout:g} s; is the sender '
                    'on simulated time?); stopping'))
                return
        holonomic = self._runner.holonomic(robot)
        if twist.linear.y != 0.0 and not holonomic:
            self.get_logger().warn(f'{robot}/cmd_vel: linear.y {twist.linear.y:.3f} ignored: a '
                                   'differential drive cannot move sideways',
                                   throttle_duration_sec=5.0)
        result = self._runner.command(robot, twist.linear.x, twist.linear.y, twist.angular.z)
        if not result.accepted:
            self._warn((robot, 'cmd_vel', 'rejected'), f'{robot}/cmd_vel: {result.reason}')
        elif result.clamped:
            asked = ((twist.linear.x, twist.linear.y, twist.angular.z) if holonomic
                     else (twist.linear.x, twist.angular.z))
            self._warn((robot, 'cmd_vel', 'clamped'),
                       f'{robot}/cmd_vel {_fmt(asked)} clamped to {_fmt(result.command)} '
                       f'(limits {_fmt(self._runner.guards[robot].limits)})')

    def _warn(self, key: tuple, message: str, kind: str = '') -> None:
        """A warning per robot, topic and kind, at most one a second, counting those held;
        every one counted for /diagnostics (under ``kind``, default the key's)."""
        self._input_report.add(key[0], key[1], kind or key[2], message)
        text = self._rejections.text(key, time.monotonic(), message)
        if text is not None:
            self.get_logger().warn(text)

    def _publish_input_report(self) -> None:
        if not self._input_report:
            return
        msg = DiagnosticArray()
        msg.header.stamp = stamp_from_ns(self._world.sim_time_ns)
        for status in self._input_report.statuses():
            msg.status.append(DiagnosticStatus(
                level=bytes([status.level]), name=f'{self.get_name()}: {status.name}',
                hardware_id=status.hardware_id, message=status.message,
                values=[KeyValue(key=k, value=v) for k, v in status.values]))
        self._diagnostics_pub.publish(msg)

    def _on_trajectory(self, robot: str, controller: str, msg: JointTrajectory) -> None:
        self._command_arrived()
        result = self._runner.set_trajectory(robot, controller, trajectory_request(msg))
        where = f'{robot}/{controller}'
        if result.accepted:
            self._actions.preempt((robot, controller), 'preempted by a trajectory on the topic')
            self.get_logger().info(f'{where}: following a trajectory of {len(msg.points)} '
                                   f'points for {list(msg.joint_names)}')
        else:
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
        service = self._suction_services[robot]
        text = f'{robot}/{service} {"on" if request.data else "off"}: {response.message}'
        # (rclpy forbids two severities from one logging call site.)
        if response.success:
            self.get_logger().info(text)
        else:
            self.get_logger().warn(text)
        return response

    def _on_set_parameters(self, params):
        for param in params:
            if param.name != 'belt_speed':
                continue
            conveyor = self._world.conveyor
            if conveyor is None:
                return SetParametersResult(successful=False, reason='this world has no conveyor')
            speed = float(param.value)
            if speed == -1.0:
                speed = conveyor.config.belt_speed            # the world file's
            elif not speed >= 0.0:
                # (The belt runs one way: a negative speed would have been "set" and ignored.)
                return SetParametersResult(successful=False, reason=(
                    f'belt_speed {speed} m/s: the belt runs forward only (>= 0, or -1 for the '
                    "world file's)"))
            conveyor.speed = speed
            self.get_logger().info(f'belt speed {speed:.3f} m/s')
        return SetParametersResult(successful=True)

    def _on_reset(self, _request, response):
        aborted = self._actions.abort_all(
            'the simulation was reset: the arm is back at its start pose', hold=False)
        faults = list(self._runner.faults)
        self._runner.reset()
        self._hold_watch = HoldWatch(self._world)     # (simulated time starts again)
        for robot in self._cmd_out_pubs:
            self._publish_applied(robot, self._world.sim_time_ns)
        for name in self._world.robots:
            self.on_state(name, self._world.sim_time_ns)
        response.success, response.message = True, 'robots returned to their start poses' + (
            f' (faults cleared: {", ".join(faults)})' if faults else '') + (
            f' (goals aborted: {", ".join(aborted)})' if aborted else '')
        self.get_logger().info('world reset' + (f'; goals aborted: {", ".join(aborted)}'
                                                if aborted else ''))
        return response

    def _on_pause(self, _request, response):
        if self._synchronous:
            response.success, response.message = False, 'synchronous mode: use ~/step'
        else:
            self._paused = True
            self._timer.cancel()
            aborted = self._actions.abort_all(
                'the simulation was paused: the arm holds where it is; send the goal again '
                'after ~/resume', hold=True)
            response.success = True
            response.message = f'paused at {self._world.sim_time:.3f} s' + (
                f' (goals aborted: {", ".join(aborted)})' if aborted else '')
        return response

    def _on_resume(self, _request, response):
        if self._synchronous:
            response.success, response.message = False, 'synchronous mode: use ~/step'
        elif self._step_jobs:
            # (Both would step the world: the reply's step count would not be the request's.)
            left = sum(job.remaining for job in self._step_jobs)
            response.success, response.message = False, (
                f'~/step requests are being served ({left} steps left): resume after their '
                'reply')
        else:
            self._paused = False
            self._pacer.restart()
            self._rtf.reset()
            self._timer.reset()
            response.success, response.message = True, 'resumed'
        return response

    def _command_arrived(self) -> None:
        self._barrier.arrived()

    def _on_step(self, request, response):
        if not (self._synchronous or self._paused):
            response.success = False
            response.message = 'step needs synchronous:=true or a paused simulation'
        elif not (1 <= request.steps <= MAX_STEPS_PER_REQUEST):
            response.success = False
            response.message = f'steps must be within 1..{MAX_STEPS_PER_REQUEST}'
        elif self._step_jobs or request.steps > self._step_chunk:
            job = _StepJob(request, response, request.steps)
            self._step_jobs.append(job)
            self._chunk_timer.reset()
            return self._step_replies.later(job)
        elif self._claim_commands(request, response):
            self._runner.advance(request.steps, self)
            self._end_step(response)
        response.step_count = self._world.step_count
        response.sim_time = stamp_from_ns(self._world.sim_time_ns)
        return response

    def _claim_commands(self, request, response) -> bool:
        """Whether the commands announced with a step request are in (taking them if so);
        if not, ``response`` says so and asks the caller to try again."""
        if not self._barrier.ready(request.commands):
            response.success, response.commands_pending = False, True
            response.message = (f'{self._barrier.received} of the {request.commands} commands '
                                'announced for this step have arrived; not stepped, ask again')
            return False
        claim = self._barrier.claim(request.commands)
        if request.commands > 0 and claim.surplus:
            self.get_logger().warn(
                f'{claim.received} commands arrived for a step announced with '
                f'{claim.expected}: another node commands this lock-step run, which is '
                'then not reproducible', throttle_duration_sec=5.0)
        return True

    def _end_step(self, response) -> None:
        self._runner.tick_clock(self)       # (the batch's end, if off the clock's grid)
        self._note_progress()
        response.success = True

    def _on_step_chunk(self) -> None:
        """Run the next chunk of the oldest step request waiting; answer it after its last."""
        if not self._step_jobs:
            self._chunk_timer.cancel()
            return
        job = self._step_jobs[0]
        done = False
        if not job.started:
            job.started = True
            done = not self._claim_commands(job.request, job.response)
        if not done:
            steps = min(job.remaining, self._step_chunk)
            self._runner.advance(steps, self)
            job.remaining -= steps
            done = job.remaining == 0
            if done:
                self._end_step(job.response)
        if done:
            self._step_jobs.popleft()
            job.response.step_count = self._world.step_count
            job.response.sim_time = stamp_from_ns(self._world.sim_time_ns)
            self._step_replies.send(job, job.response)
        if not self._step_jobs:
            self._chunk_timer.cancel()

    def destroy_node(self) -> None:
        # Leave no robot driving on a stale command.
        self._runner.stop_all()
        self._world.close()
        super().destroy_node()


@dataclass(eq=False)
class _StepJob:
    """A ~/step request served in chunks, and the reply it will get."""
    request: StepSimulation.Request
    response: StepSimulation.Response
    remaining: int
    started: bool = False


def _topic(namespace: str, name: str) -> str:
    # Relative names, so a node namespace or remapping applies on top of the robot namespace.
    return f'{namespace}/{name}' if namespace else name


def _fmt(values) -> str:
    return '(' + ', '.join(f'{v:.3f}' for v in values) + ')'


def trajectory_request(msg: JointTrajectory) -> TrajectoryRequest:
    """A JointTrajectory as the follower takes it (a zero stamp means "start now")."""
    stamp = msg.header.stamp
    start = None if stamp.sec == 0 and stamp.nanosec == 0 else to_seconds(stamp)
    points = tuple(TrajectoryPoint(to_seconds(p.time_from_start), tuple(p.positions),
                                   tuple(p.velocities), tuple(p.accelerations), tuple(p.effort))
                   for p in msg.points)
    return TrajectoryRequest(tuple(msg.joint_names), points, start)


def _transform(t: FrameTransform, stamp: Time) -> TransformStamped:
    out = TransformStamped()
    out.header.stamp = stamp
    out.header.frame_id, out.child_frame_id = t.parent, t.child
    tr, q = out.transform.translation, out.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in t.translation)
    q.x, q.y, q.z, q.w = (float(v) for v in t.rotation)
    return out


# Numbers in a rejection's reason: two reasons that differ only in them are of one kind.
_NUMBERS = re.compile(r'-?\d[\d.e+-]*|nan|inf')


def _wanted(publisher) -> bool:
    """Someone reads this topic now."""
    return publisher.get_subscription_count() > 0


def _controller_state(group, stamp: Time) -> JointTrajectoryControllerState:
    """control_msgs' state of a joint trajectory controller. reference and feedback are
    repeated in the deprecated desired and actual (Jazzy's JTC fills both)."""
    desired = group.desired
    position, velocity = group.actual()
    msg = JointTrajectoryControllerState(joint_names=list(group.joint_names))
    msg.header.stamp = stamp
    fill_points(msg.reference, msg.feedback, msg.error, desired, position, velocity)
    msg.reference.accelerations = desired.accelerations.tolist()
    msg.output.positions = desired.positions.tolist()
    msg.output.effort = group.limits.effort.tolist()
    msg.desired, msg.actual = msg.reference, msg.feedback
    return msg


def _material_marker(material, pos, rot, state: str, config, stamp: Time) -> Marker:
    marker = Marker(ns=material.color, id=material.index, type=Marker.CUBE,
                    action=Marker.ADD, text=state)
    marker.header.stamp = stamp
    marker.header.frame_id = 'world'
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (
        float(v) for v in pos)
    o = marker.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(rot)
    marker.scale.x = marker.scale.y = marker.scale.z = material.size
    r, g, b, a = dict(config.colors)[material.color]
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = r, g, b, a
    return marker


def main(args=None) -> int:
    # SIGINT and SIGTERM end the spin between two callbacks: rclpy's own handler shut the
    # context down under a running timer, which then failed to publish ('[FATAL] Exception
    # in 'timers' callback: ... publisher's context is invalid').
    return run_node(SimNode, 'sim_node',
                    (SimConfigError, WorldConfigError, WorldError, FileNotFoundError), args=args,
                    graceful_signals=True)


if __name__ == '__main__':
    sys.exit(main())
