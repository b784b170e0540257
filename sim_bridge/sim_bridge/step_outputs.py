"""What a step of the simulator produces, published (the ``StepSink`` of runner.py): the clock,
each robot's joint states, odometry, controller states, suction state and applied command, TF
and the robots' descriptions, the materials, the camera frames, and the faults. A message
nobody reads is not built or sent."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from builtin_interfaces.msg import Time
from control_msgs.msg import JointTrajectoryControllerState
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState, LaserScan
from sim_interfaces.msg import GripState
from std_msgs.msg import Bool, String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from robot_description import with_frame_prefix
from ros_common.stamps import stamp_from_ns
from sim_bridge import messages
from sim_bridge.base_clearance import Closest
from sim_bridge.belt_encoder import BELT_JOINT, ENCODER_TOPIC, BeltEncoder
from sim_bridge.camera import ImageBuffer
from sim_bridge.frames import WorldFrames
from sim_bridge.hold_watch import HoldWatch
from sim_bridge.joint_speed import Braked
from sim_bridge.laser import LaserScanner
from sim_bridge.messages import topic
from sim_bridge.node_diagnostics import LATCHED, NodeDiagnostics
from sim_bridge.runner import SimRunner, Twist3
from sim_bridge.world import SimWorld

# A reliable writer keeps only `depth` samples for a reader that falls behind: 100 lets a
# recorder starved for a moment (or a lock-step burst) still receive every message.
HISTORY = QoSProfile(depth=100)


@dataclass
class _RobotIO:
    """One robot's publishers."""
    joints: Publisher
    frames: Tuple[str, str]                  # its odom and base_link frames
    odom: Optional[Publisher] = None
    cmd_out: Optional[Publisher] = None      # for a driven base
    holding: Optional[Tuple[Publisher, Publisher]] = None
    states: Dict[str, Publisher] = field(default_factory=dict)    # per controller
    scan: Optional[Tuple[Publisher, LaserScanner, LaserScan]] = None   # its laser scanner


@dataclass
class _CameraIO:
    """One camera's publishers, and the messages its frames are written into."""
    image: Publisher
    jpeg: Publisher
    info: Publisher
    image_msg: Image
    info_msg: CameraInfo
    buffer: ImageBuffer


@dataclass(frozen=True)
class OutputOptions:
    link_tf: bool                          # every link's frame on /tf (else the anchors)
    jpeg_quality: int
    camera_reliability: ReliabilityPolicy


class StepOutputs:
    def __init__(self, node: Node, world: SimWorld, runner: SimRunner, actions: Any,
                 diagnostics: NodeDiagnostics, options: OutputOptions) -> None:
        self._node, self._world, self._runner = node, world, runner
        self._actions, self._diagnostics, self._options = actions, diagnostics, options
        self._clock_pub = node.create_publisher(ClockMsg, '/clock', HISTORY)
        self._clock_msg = ClockMsg()
        self._robots = {name: self._robot_io(name) for name in world.robots}
        self._cameras = [self._camera_io(cam) for cam in world.cameras]
        self._start_tf()
        self.hold_watch = HoldWatch(world)
        self._materials_pub = (node.create_publisher(MarkerArray, '/cell/materials', HISTORY)
                               if world.source is not None else None)
        # The conveyor drive's encoder, where the world gives the cell one.
        conveyor = world.conveyor
        self._encoder = (BeltEncoder(conveyor.config.encoder, world.source.seed)
                         if conveyor is not None and world.source is not None
                         and conveyor.config.encoder is not None else None)
        self._encoder_pub = (node.create_publisher(JointState, ENCODER_TOPIC, HISTORY)
                             if self._encoder is not None else None)

    # --- start-up -----------------------------------------------------------------------------
    def _robot_io(self, name: str) -> _RobotIO:
        robot, node = self._world.robots[name], self._node
        ns, prefix = robot.config.namespace, robot.config.frame_prefix
        io = _RobotIO(node.create_publisher(JointState, topic(ns, 'joint_states'), HISTORY),
                      (prefix + 'odom', prefix + 'base_link'))
        if not robot.config.fixed_base:
            io.odom = node.create_publisher(Odometry, topic(ns, 'odom'), HISTORY)
        suction = robot.config.suction
        if name in self._world.suctions and suction is not None:
            service = topic(ns, suction.service)
            # The cup's vacuum switch: true while it holds a part; and the same, stamped.
            io.holding = (node.create_publisher(Bool, f'{service}/holding', HISTORY),
                          node.create_publisher(GripState, f'{service}/state', HISTORY))
        if name in self._runner.guards:
            # The command as applied (clamped, zeroed on bad input or by the timeout), when it
            # changes and stamped when it took effect: diff_drive_controller's cmd_vel_out.
            # Transient local: a checker that joins late still gets the first changes.
            io.cmd_out = node.create_publisher(
                TwistStamped, topic(ns, 'cmd_vel_out'),
                QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        laser = robot.config.laser
        if laser is not None:
            scanner = LaserScanner(self._world.client, laser, name,
                                   self._world.source.seed if self._world.source else 0)
            msg = LaserScan(angle_min=float(scanner.angles[0]),
                            angle_max=float(scanner.angles[-1]),
                            angle_increment=scanner.angle_increment, scan_time=1.0 / laser.rate,
                            range_min=laser.range_min, range_max=laser.range_max)
            msg.header.frame_id = prefix + 'laser'
            io.scan = (node.create_publisher(LaserScan, topic(ns, 'scan'), HISTORY), scanner,
                       msg)
        for controller in robot.controllers:
            io.states[controller] = node.create_publisher(
                JointTrajectoryControllerState, topic(ns, f'{controller}/controller_state'),
                HISTORY)
        return io

    def _camera_io(self, cam: Any) -> _CameraIO:
        c, node = cam.config, self._node
        ns = self._world.robots[c.robot].config.namespace if c.robot else ''
        # Reliable by default, keeping a second of frames: best-effort readers (the
        # sensor-data profile, as the vision node reads) match it too, and reliable ones (a
        # recorder, RViz's and rqt's defaults) get every frame after a stall of up to a second.
        qos = QoSProfile(depth=max(5, math.ceil(c.rate)),
                         reliability=self._options.camera_reliability)
        image = Image(height=c.height, width=c.width, encoding='rgb8', is_bigendian=0,
                      step=3 * c.width, data=bytes(3 * c.width * c.height))
        image.header.frame_id = c.frame_id
        return _CameraIO(
            node.create_publisher(Image, topic(ns, f'{c.name}/image_raw'), qos),
            # image_transport's compressed transport: JPEG, encoded only while subscribed.
            node.create_publisher(CompressedImage, topic(ns, f'{c.name}/image_raw/compressed'),
                                  qos),
            node.create_publisher(CameraInfo, topic(ns, f'{c.name}/camera_info'), qos),
            image, messages.camera_info(c, cam.intrinsics),
            # Frames are written into the message's own byte array (see ImageBuffer).
            ImageBuffer(c.width, c.height, image.data))

    def _start_tf(self) -> None:
        """TF (frames.py): moving frames on /tf at the state rate while someone listens; the
        rest once on /tf_static, latched. And each robot's URDF, its links named with its
        frame prefix, latched as robot_state_publisher offers it (what RViz and Foxglove draw
        the robot from)."""
        node = self._node
        self._frames = WorldFrames(self._world)
        self._tf_pub = node.create_publisher(TFMessage, '/tf', HISTORY)
        self._tf_static_pub = node.create_publisher(TFMessage, '/tf_static', LATCHED)
        static = self._frames.static()
        if not self._options.link_tf:
            # (robot_state_publisher publishes the fixed joints from the robot_description.)
            anchors = {f.anchor().child for f in self._frames.robots.values()}
            cameras = {c.config.frame_id for c in self._world.cameras if c.robot is None}
            # (A laser scanner is the world's, not in the URDF.)
            lasers = {r.config.frame_prefix + 'laser' for r in self._world.robots.values()
                      if r.config.laser is not None}
            static = [t for t in static if t.child in anchors | cameras | lasers]
        stamp = stamp_from_ns(self._world.sim_time_ns)
        self._tf_static_pub.publish(TFMessage(transforms=[messages.transform(t, stamp)
                                                          for t in static]))
        self._description_pubs: List[Publisher] = []
        for robot in self._world.robots.values():
            pub = node.create_publisher(String, topic(robot.config.namespace,
                                                      'robot_description'), LATCHED)
            pub.publish(String(data=with_frame_prefix(robot.urdf.read_text(),
                                                      robot.config.frame_prefix)))
            self._description_pubs.append(pub)

    # --- StepSink: what a step produces -------------------------------------------------------
    def on_clock(self, time_ns: int) -> None:
        self._clock_msg.clock = stamp_from_ns(time_ns)
        self._clock_pub.publish(self._clock_msg)

    def on_trajectory_aborted(self, robot: str, controller: str, reason: str) -> None:
        self._actions.abort((robot, controller), reason)
        self._diagnostics.trajectory_refused(
            robot, controller, 'aborted', reason, (robot, controller, 'aborted'),
            f'{robot}/{controller}: trajectory aborted: {reason}; holding position')

    def on_fault(self, robot: str, reason: str) -> None:
        for controller in self._world.robots[robot].controllers:
            self._actions.abort((robot, controller), reason)
        self._node.get_logger().error(
            f'{reason}: {robot} was stopped and put back at its start pose, at rest; it takes '
            'no commands or trajectories until ~/reset')
        if robot in self._runner.guards:
            self.publish_applied(robot, self._world.sim_time_ns, self._runner.applied(robot))

    def on_body_lost(self, name: str, what: str) -> None:
        self._node.get_logger().error(f'{name}: {what}')

    def on_joints_braked(self, robot: str, time_ns: int, braked: Sequence[Braked]) -> None:
        self._diagnostics.joints_braked(robot, time_ns, braked)

    def on_bases_closest(self, closest: Closest) -> None:
        self._diagnostics.bases_closest(closest)

    def on_state(self, robot: str, time_ns: int) -> None:
        # A state nobody reads is not built or sent (as the cameras): each costs about a
        # millisecond in rclpy, and a lock-step trial sends about 20,000 of them. A reader that
        # joins gets the next one.
        stamp = stamp_from_ns(time_ns)
        sim_robot, io = self._world.robots[robot], self._robots[robot]
        if wanted(self._tf_pub):
            moving = self._frames.moving(robot, links=self._options.link_tf)
            if moving:
                self._tf_pub.publish(TFMessage(transforms=[messages.transform(t, stamp)
                                                           for t in moving]))
        self._actions.on_state(robot, time_ns * 1e-9)
        for report in self.hold_watch.update(time_ns * 1e-9):
            # (One call site per severity: rclpy refuses a call site whose severity changes.)
            if report.blocked:
                self._node.get_logger().warning(report.text)
            else:
                self._node.get_logger().info(report.text)
        if wanted(io.joints):
            io.joints.publish(messages.joint_state(sim_robot.sensors.joint_states(), stamp))
        if io.holding is not None:
            self._publish_suction(robot, io.holding, stamp)
        for name, group in sim_robot.controllers.items():
            if wanted(io.states[name]):
                io.states[name].publish(messages.controller_state(group, stamp))
        if io.odom is not None and wanted(io.odom):
            io.odom.publish(messages.odometry(sim_robot.sensors.base_state(), io.frames, stamp))

    def _publish_suction(self, robot: str, pubs: Tuple[Publisher, Publisher],
                         stamp: Time) -> None:
        suction = self._world.suctions[robot]
        holding = suction.held is not None
        bool_pub, state_pub = pubs
        if wanted(bool_pub):
            bool_pub.publish(Bool(data=holding))
        if wanted(state_pub):
            grip = GripState(armed=suction.armed, holding=holding)
            grip.header.stamp = stamp
            state_pub.publish(grip)

    def on_belt(self, time_ns: int) -> None:
        if self._encoder is None or self._encoder_pub is None or self._world.conveyor is None:
            return
        # (Read whether or not anyone listens: its speed is over the period since.)
        travel, speed = self._encoder.read(time_ns * 1e-9, self._world.conveyor.travel)
        if wanted(self._encoder_pub):
            msg = JointState(name=[BELT_JOINT], position=[travel], velocity=[speed])
            msg.header.stamp = stamp_from_ns(time_ns)
            self._encoder_pub.publish(msg)

    def on_scan(self, robot: str, time_ns: int) -> None:
        scan = self._robots[robot].scan
        if scan is None or not wanted(scan[0]):
            return
        pub, scanner, msg = scan
        msg.header.stamp = stamp_from_ns(time_ns)
        msg.ranges = scanner.scan(self._world.robots[robot].base_link_world(), time_ns).tolist()
        pub.publish(msg)

    def on_world_state(self, time_ns: int) -> None:
        if self._materials_pub is None or not wanted(self._materials_pub):
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

    def on_camera_due(self, index: int, time_ns: int, render: Callable[[], Any]) -> None:
        # Rendering dominates the cost of a step: only for image subscribers.
        stamp = stamp_from_ns(time_ns)
        cam = self._cameras[index]
        raw, jpeg = wanted(cam.image), wanted(cam.jpeg)
        if raw or jpeg:
            rgba = render()
            if raw:
                cam.buffer.fill_from_rgba(rgba)
                cam.image_msg.header.stamp = stamp
                cam.image.publish(cam.image_msg)
            compressed = self._jpeg(cam, rgba, stamp) if jpeg else None
            if compressed is not None:
                cam.jpeg.publish(compressed)
        elif not wanted(cam.info):
            return
        cam.info_msg.header.stamp = stamp
        cam.info.publish(cam.info_msg)

    def _jpeg(self, cam: _CameraIO, rgba: Any, stamp: Time) -> Optional[CompressedImage]:
        import cv2  # (only for a compressed-image subscriber)
        ok, data = cv2.imencode('.jpg', cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, self._options.jpeg_quality])
        if not ok:
            self._node.get_logger().error('a camera frame could not be encoded as JPEG',
                                          throttle_duration_sec=5.0)
            return None
        msg = CompressedImage(format='rgb8; jpeg compressed bgr8', data=data.tobytes())
        msg.header.stamp = stamp
        msg.header.frame_id = cam.image_msg.header.frame_id
        return msg

    def on_command_timeout(self, robot: str) -> None:
        self._node.get_logger().info(
            f'{robot}: no cmd_vel for {self._runner.guards[robot].timeout} s; stopping',
            throttle_duration_sec=5.0)

    def on_command_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        self.publish_applied(robot, time_ns, command)

    def publish_applied(self, robot: str, time_ns: int, command: Twist3) -> None:
        io = self._robots[robot]
        if io.cmd_out is not None:
            io.cmd_out.publish(messages.applied_twist(command, io.frames[1],
                                                      stamp_from_ns(time_ns)))


def wanted(publisher: Publisher) -> bool:
    """Someone reads this topic now."""
    return bool(publisher.get_subscription_count() > 0)
