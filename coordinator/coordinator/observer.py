"""What the coordinator sees of the cell, over ROS: the arms' joint states and grips, the base's
odometry (in the cell's frame), the vision's detections, the simulator's ground truth (for the
score) and what it braked; and the run's clock. In lock-step it requests every step and, before
each decision, waits for the messages of exactly that step (states stamped with its time, the
detections of every camera frame it produced): the same seed gives the same run."""
from __future__ import annotations

import functools
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from sim_interfaces.msg import GripState, MaterialDetectionArray
from sim_interfaces.srv import StepSimulation
from visualization_msgs.msg import MarkerArray

from cell_layout.joint_speeds import driven_past
from cell_layout.layout import CellLayout
from controllers.cell_odometry import odometry_in_cell
from controllers.lockstep import CommandCounter, DueGrid
from controllers.path_follower import DriveLead, PathFollower
from coordinator.pipeline import (
    ArmReading,
    BaseReading,
    Detection,
    Material,
    NodeTimeout,
    Observation,
)
from coordinator.ros_ports import Stopped, call_service
from ros_common.geometry import yaw_of
from ros_common.stamps import to_ns
from trial_record.scoring import IdentificationCheck, PeakJointSpeed
from world_description.graph_names import BELT_ENCODER_TOPIC

CAMERA_TOPIC = '/belt_camera/image_raw'
STARTUP_GRACE_S = 1.0      # simulated seconds in which a lost camera frame is tolerated
STOP_CHECK_S = 0.2         # wall seconds between looks at a stop while waiting


class Inputs:
    """What the coordinator hears, as it comes (the executor's threads): the arms' joint states
    (and the peaks of their speeds), the grips, the base's odometry in the cell's frame, the
    vision's detections by frame, the ground truth, what the simulator braked. ``lock`` guards
    it all and is notified as each message is taken in. ``now``: the run's clock; ``drive``:
    the base's command, for the path follower run on every odometry message in real time."""

    def __init__(self, node: Node, layout: CellLayout, arms: Mapping[str, Sequence[str]],
                 sim: str, synchronous: bool, drive_lead: float,
                 speed_joints: Dict[str, Dict[str, float]], now: Callable[[], float],
                 drive: Callable[[str, float, float, float], None]) -> None:
        self.node, self.layout, self.arms, self.synchronous = node, layout, arms, synchronous
        self.now, self.drive = now, drive
        self.lock = threading.Condition()
        # arm: (stamp [ns], positions, velocities if the message has them)
        self.joints: Dict[str, Tuple[int, np.ndarray, Optional[np.ndarray]]] = {}
        self.grip: Dict[str, Tuple[int, bool, bool]] = {}      # arm: (stamp, holding, armed)
        # Each base's (stamp, pose in the cell (x, y, yaw), velocity (vx, vy in the cell, wz)).
        self.odom: Dict[str, Tuple[int, Tuple[float, float, float],
                                   Tuple[float, float, float]]] = {}
        self._follower: Dict[str, PathFollower] = {}        # real time: each base's drive
        self.drive_lead = DriveLead(drive_lead)
        self.detections: Dict[int, List[Detection]] = {}   # by camera frame stamp [ns]
        self.markers: List[Tuple[int, list]] = []           # the ground truth, newest last
        self.identifications = IdentificationCheck()
        # Every joint with a speed limit in each robot's URDF (arm, gripper, wheels), as the
        # simulator's joint states report it; and what the simulator braked (~/joint_limits).
        self.speed_joints = speed_joints
        self.peak = {arm: PeakJointSpeed(list(limits.values()))
                     for arm, limits in speed_joints.items()}
        self.driven_past: List[Dict[str, Any]] = []
        self.closest_bases: Optional[Dict[str, Any]] = None    # (the simulator's, latched)
        self.belt: List[Tuple[int, float]] = []     # the encoder's (stamp [ns], travel) read
        self.belt_stamp = -1
        self._subscribe(sim)

    def _subscribe(self, sim: str) -> None:
        node, qos = self.node, QoSProfile(depth=100)
        for arm, names in self.arms.items():
            robot = self.layout.robots[arm]
            node.create_subscription(JointState, robot.topic('joint_states'),
                                     functools.partial(self._on_joints, arm, names), qos)
            node.create_subscription(GripState, f'{robot.grip}/state',
                                     functools.partial(self._on_grip, arm), qos)
        # Real time: the drive acts on the newest odometry only (one the executor could not
        # take in time is stale); lock-step waits for the stamp of every state.
        for base in self.layout.transports:
            node.create_subscription(Odometry, base.topic('odom'),
                                     functools.partial(self._on_odom, base.name),
                                     qos if self.synchronous else QoSProfile(depth=1))
        self._detections_sub: Optional[Subscription] = node.create_subscription(
            MaterialDetectionArray, '/detections', self._on_detections, qos)
        node.create_subscription(MarkerArray, '/cell/materials', self._on_markers, qos)
        if self.layout.belt_encoder > 0.0:
            node.create_subscription(JointState, BELT_ENCODER_TOPIC, self._on_belt, qos)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(DiagnosticArray, f'{sim}/joint_limits', self._on_joint_limits,
                                 latched)
        node.create_subscription(DiagnosticArray, f'{sim}/base_clearance',
                                 self._on_base_clearance, latched)

    # --- inputs -------------------------------------------------------------------------------
    def _on_joints(self, arm: str, names: Sequence[str], msg: JointState) -> None:
        index = {n: i for i, n in enumerate(msg.name)}
        if len(msg.position) != len(msg.name) or not all(n in index for n in names):
            self.node.get_logger().warn(f'/{arm}/joint_states without the arm joints ignored',
                                   throttle_duration_sec=5.0)
            return
        velocity = (np.array([msg.velocity[index[n]] for n in names])
                    if len(msg.velocity) == len(msg.name) else None)
        limited = self.speed_joints[arm]
        speeds = (np.array([msg.velocity[index[n]] for n in limited])
                  if velocity is not None and all(n in index for n in limited) else None)
        with self.lock:
            self.joints[arm] = (to_ns(msg.header.stamp),
                                 np.array([msg.position[index[n]] for n in names]), velocity)
            if speeds is not None:
                self.peak[arm].update(speeds, to_ns(msg.header.stamp) * 1e-9)
            self.lock.notify_all()

    def _on_belt(self, msg: JointState) -> None:
        if 'belt' not in msg.name or len(msg.position) != len(msg.name):
            self.node.get_logger().warn(f'{BELT_ENCODER_TOPIC} without the belt joint ignored',
                                        throttle_duration_sec=5.0)
            return
        with self.lock:
            self.belt_stamp = to_ns(msg.header.stamp)
            self.belt.append((self.belt_stamp, float(msg.position[msg.name.index('belt')])))
            self.lock.notify_all()

    def _on_joint_limits(self, msg: DiagnosticArray) -> None:
        driven = driven_past(msg)
        with self.lock:
            self.driven_past = driven

    def _on_base_clearance(self, msg: DiagnosticArray) -> None:
        values = {kv.key: kv.value for s in msg.status for kv in s.values}
        try:
            closest = {'distance': float(values['distance']), 'time': float(values['time']),
                       'robots': values['robots'].split(',')}
        except (KeyError, ValueError):
            return
        with self.lock:
            self.closest_bases = closest

    def _on_grip(self, arm: str, msg: GripState) -> None:
        with self.lock:
            self.grip[arm] = (to_ns(msg.header.stamp), bool(msg.holding), bool(msg.armed))
            self.lock.notify_all()

    def _on_odom(self, base: str, msg: Odometry) -> None:
        p, q, v = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        pose, world = odometry_in_cell(self.layout.park(base), p.x, p.y, yaw_of(q),
                                       v.linear.x, v.linear.y, v.angular.z)
        stamp = to_ns(msg.header.stamp) * 1e-9
        with self.lock:
            self.odom[base] = (to_ns(msg.header.stamp), pose, world)
            self.lock.notify_all()
            follower = self._follower.get(base)
            if follower is not None:
                # Real time: the base controller, on every odometry message. A decision held
                # up by IK calls must not leave the base running on its last command. The
                # command takes effect after the odometry's trip here and its own back: the
                # follower predicts the pose that far ahead.
                status = follower.update(stamp, pose, world[:2], world[2],
                                         lead=self.drive_lead.lead(self.now() - stamp))
                self.drive(base, *status.command)

    def _on_detections(self, msg: MaterialDetectionArray) -> None:
        stamp = to_ns(msg.header.stamp)
        dets = [Detection(d.id, d.color, np.array([d.position.x, d.position.y, d.position.z]),
                          stamp * 1e-9, d.hits) for d in msg.detections]
        with self.lock:
            self.detections[stamp] = dets
            self.lock.notify_all()

    def _on_markers(self, msg: MarkerArray) -> None:
        if not msg.markers:
            return
        truth = [(m.ns, np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z]))
                 for m in msg.markers]
        with self.lock:
            self.markers.append((to_ns(msg.markers[0].header.stamp), truth))
            del self.markers[:-50]
            self.identifications.truth(self.markers[-1][0], truth)
            self.lock.notify_all()

    def set_follower(self, base: str, follower: Optional[PathFollower]) -> bool:
        """Real time: run ``follower`` on every odometry message of ``base`` (None: no
        more)."""
        with self.lock:
            if follower is None:
                self._follower.pop(base, None)
            else:
                self._follower[base] = follower
            return follower is not None

    def drop_detections(self) -> None:
        """No more detections: the reader goes."""
        if self._detections_sub is not None:
            self.node.destroy_subscription(self._detections_sub)
            self._detections_sub = None

    def check_identification(self, m: Optional[Material]) -> None:
        """A material the pipeline has confirmed (None: not known to it), as the vision reported
        it."""
        with self.lock:
            if m is None or m.detection is None:
                self.identifications.unknown()
            else:
                # The vision's own report, at its frame's time: not where the belt model has
                # carried it since (in real time the coordinator may see a frame late).
                d = m.detection
                self.identifications.seen(round(d.stamp * 1e9), d.position, d.color, m.id)

    def have_states(self) -> bool:
        """Every arm's joints and grip and every base's odometry have come (under the
        lock)."""
        arms = len(self.layout.robots)
        return (len(self.joints) == arms and len(self.grip) == arms
                and len(self.odom) == len(self.layout.transports))


class Observer:
    """The run's clock and its observations: in lock-step it requests every step and waits for
    exactly its messages; in real time it follows the simulator's clock. ``inputs``: what it
    has heard (``Inputs``)."""

    def __init__(self, node: Node, layout: CellLayout, arms: Mapping[str, Sequence[str]],
                 sim: str, synchronous: bool, rate: float, dt_ns: int, state_period_ns: int,
                 camera_period_ns: Optional[int], encoder_period_ns: Optional[int],
                 service_timeout: float, drive_lead: float,
                 commands: CommandCounter, speed_joints: Dict[str, Dict[str, float]],
                 drive: Callable[[str, float, float, float], None]) -> None:
        self.node, self.layout = node, layout
        self.synchronous, self.rate, self.dt_ns = synchronous, rate, dt_ns
        self.service_timeout, self._commands = service_timeout, commands
        # Lock-step: the simulated time of the last step the simulator reported [ns].
        self._lockstep_ns = 0
        self.steps_per_tick = max(1, round(1e9 / rate / dt_ns))
        self.state_grid = DueGrid(dt_ns, state_period_ns)
        self.camera_grid = (DueGrid(dt_ns, camera_period_ns) if camera_period_ns else None)
        # The conveyor drive's encoder, where the cell has one (its own rate).
        self.encoder_grid = (DueGrid(dt_ns, encoder_period_ns) if encoder_period_ns else None)
        self._start_time = 0.0
        self.inputs = Inputs(node, layout, arms, sim, synchronous, drive_lead, speed_joints,
                             self.now, drive)
        self.step_client = node.create_client(StepSimulation, f'{sim}/step')
        self.param_get_client = node.create_client(GetParameters, f'{sim}/get_parameters')

    def _call(self, client, request, what: str, idempotent: bool = True):
        return call_service(client, request, what, self.service_timeout, idempotent)

    def now(self) -> float:
        if self.synchronous:
            return self._lockstep_ns * 1e-9
        return self.node.get_clock().now().nanoseconds * 1e-9

    @property
    def start_time(self) -> float:
        return self._start_time

    def stop_frames(self) -> None:
        """No material will be seen again: the detections' reader goes, and with it the vision
        node's frames (it is lazy) and the simulator's rendering of them; lock-step waits for
        no frame any more."""
        self.camera_grid = None
        self.inputs.drop_detections()

    def belt_runs_at_layout_speed(self) -> bool:
        """Whether the simulator's belt already runs at the run's speed: started with its belt
        on, a real-time simulator carried the materials on before this node began, and the
        pipeline's belt model must count that ride."""
        reply = self._call(self.param_get_client, GetParameters.Request(names=['belt_speed']),
                           'belt speed')
        if not reply.values or reply.values[0].type != ParameterType.PARAMETER_DOUBLE:
            raise NodeTimeout('the simulator has no belt_speed parameter')
        speed = reply.values[0].double_value
        return speed > 0.0 and abs(speed - self.layout.belt_speed) < 1e-9

    def _step(self, steps: int) -> Tuple[int, int]:
        """Lock-step: advance; returns (step count before, after)."""
        request = StepSimulation.Request(steps=steps, commands=self._commands.take())
        reply = self._call(self.step_client, request, 'step', idempotent=False)
        # Some announced commands were not in yet (DDS orders only per writer): ask again,
        # soon at first, then backing off, until they are or the service timeout passes (the
        # condition is the simulator's: nothing here is told when it holds).
        end, pause = time.monotonic() + self.service_timeout, 0.0002
        while not reply.success and reply.commands_pending:
            if time.monotonic() > end:
                raise NodeTimeout(f'the simulator never got the commands of this step: '
                                  f'{reply.message}')
            time.sleep(pause)
            pause = min(2 * pause, 0.005)
            reply = self._call(self.step_client, request, 'step', idempotent=False)
        if not reply.success:
            raise NodeTimeout(f'the simulator refused to step: {reply.message} (is it running '
                              'with synchronous:=true?)')
        self._lockstep_ns = int(reply.step_count) * self.dt_ns
        return int(reply.step_count) - steps, int(reply.step_count)

    def _wait_for_graph(self, others: Sequence[Any]) -> None:
        """Until the nodes the run needs are up: services, the vision node on the camera."""
        clients = list(others) + [self.param_get_client]
        if self.synchronous:
            clients.append(self.step_client)
        end = time.monotonic() + self.service_timeout
        # The graph is looked at every 20 ms: rclpy gives Python no wait on a graph change (its
        # own wait_for_service sleeps in quarters of a second, one client after another: up to
        # two seconds of a trial's start-up for services that were up long before).
        while True:
            missing = [c.srv_name for c in clients if not c.service_is_ready()]
            if not missing:
                break
            if time.monotonic() > end:
                raise NodeTimeout(f'{", ".join(missing)} not available')
            time.sleep(0.02)
        if self.synchronous:
            # A step's reply must reach this node: one that steps nothing, sent again until
            # it is answered, is the first (Fast DDS drops a reply while its server has not
            # matched the client's reader; a lost first step ended a run in node_timeout).
            self._call(self.step_client, StepSimulation.Request(steps=0), 'step')
        while time.monotonic() < end:
            if (self.node.count_publishers('/detections') > 0
                    and self.node.count_subscribers(CAMERA_TOPIC) > 0):
                return
            time.sleep(0.05)
        raise NodeTimeout(f'no vision node: nothing publishes /detections or subscribes '
                          f'{CAMERA_TOPIC}')

    def first(self, clients: Sequence[Any]) -> Observation:
        """The run's first observation, once the graph is up (``clients``: the services the
        run calls besides the simulator's)."""
        self._wait_for_graph(clients)
        if self.synchronous:
            before, after = self._step(self.steps_per_tick)
            self._start_time = after * self.dt_ns * 1e-9
            self.state_grid.start_after(after * self.dt_ns)
            for grid in (self.camera_grid, self.encoder_grid):
                if grid:
                    grid.start_after(after * self.dt_ns)
            self._wait_states(after * self.dt_ns, first=True)
            return self._observe(after * self.dt_ns, [])
        end = time.monotonic() + self.service_timeout
        with self.inputs.lock:
            # (Woken by each state message; the clock runs with them.)
            if not self._wait(lambda: self.inputs.have_states() and self.now() > 0.0,
                              self.service_timeout):
                raise NodeTimeout('no joint_states, grip states and odometry from the '
                                  'simulator (is sim_node running with the cell world?)')
        # Real time: the belt starts with the first decision, so not before the camera's frames
        # reach this node through the vision node. The graph being up does not say that: the
        # vision node subscribes to the camera only once it sees this node's reader (lazy), and
        # then the simulator and the vision node have to match each other. On a busy machine
        # that took seconds of simulated time, in which the first two materials rode past the
        # camera unseen (the purple, held at the end stop behind one of them, was then picked
        # where that one stood). A detections message is answered for a frame: they flow.
        with self.inputs.lock:
            if not self._wait(lambda: bool(self.inputs.detections), end - time.monotonic()):
                raise NodeTimeout(f'no detections from the vision node: no camera frame reached '
                                  f'it through {CAMERA_TOPIC}, or its answers did not reach '
                                  f'this node')
        return self._observe(round(self.now() * 1e9), None)

    def next(self, obs: Observation) -> Observation:
        if not self.synchronous:
            # Until the clock reaches the next decision: woken by each state message (the
            # clock runs with them), and at least every 5 ms (a poll at 1 kHz cost a tenth of
            # a core).
            target = obs.now + 1.0 / self.rate
            end = time.monotonic() + self.service_timeout
            with self.inputs.lock:
                while self.now() < target:
                    if time.monotonic() > end:
                        raise NodeTimeout('the simulated clock stopped (simulator gone?)')
                    if not rclpy.ok():
                        raise Stopped()
                    self.inputs.lock.wait(0.005)
            return self._observe(round(self.now() * 1e9), None)
        before, after = self._step(self.steps_per_tick)
        state_due = self.state_grid.advance(before, after)
        frames = self.camera_grid.advance(before, after) if self.camera_grid else []
        if state_due:
            self._wait_states(state_due[-1])
        belt_due = self.encoder_grid.advance(before, after) if self.encoder_grid else []
        if belt_due:
            self._wait_belt(belt_due[-1])
        self._wait_frames(frames)
        return self._observe(after * self.dt_ns, frames)

    def _wait(self, ready: Callable[[], bool], timeout: float) -> bool:
        """Under the lock: until ``ready()`` (True) or ``timeout`` seconds (False), woken by
        what the callbacks deliver; a stop (Ctrl-C, SIGTERM) ends the wait at once (Stopped):
        the simulator and the vision node stop with this node, and nothing will come."""
        end = time.monotonic() + timeout
        while not ready():
            if not rclpy.ok():
                raise Stopped()
            left = end - time.monotonic()
            if left <= 0.0:
                return False
            self.inputs.lock.wait(min(left, STOP_CHECK_S))
        return True

    def _wait_states(self, stamp_ns: int, first: bool = False) -> None:
        heard = self.inputs

        def ready() -> bool:
            stamps = [j[0] for j in heard.joints.values()] + [g[0] for g in heard.grip.values()]
            stamps += [o[0] for o in heard.odom.values()]
            if len(stamps) < 2 * len(self.layout.robots) + len(self.layout.transports):
                return False
            if first and self.encoder_grid and heard.belt_stamp < 0:
                return False            # (its first reading, at the first step)
            return all(s >= stamp_ns for s in stamps) if first else \
                all(s == stamp_ns for s in stamps)
        with self.inputs.lock:
            if not self._wait(ready, self.service_timeout):
                have = {**{f'{a} joints': j[0] for a, j in self.inputs.joints.items()},
                        **{f'{a} grip': g[0] for a, g in self.inputs.grip.items()},
                        **{f'{b} odom': o[0] for b, o in self.inputs.odom.items()},
                        'belt encoder': self.inputs.belt_stamp}
                raise NodeTimeout(f'no states from the simulator for t = {stamp_ns * 1e-9:.3f} s'
                                  f' (latest stamps [ns]: {have})')

    def _wait_belt(self, stamp_ns: int) -> None:
        """Until the encoder's reading stamped ``stamp_ns`` is in."""
        with self.inputs.lock:
            if not self._wait(lambda: self.inputs.belt_stamp == stamp_ns, self.service_timeout):
                raise NodeTimeout(f'no belt encoder reading from the simulator for t = '
                                  f'{stamp_ns * 1e-9:.3f} s (latest: '
                                  f'{self.inputs.belt_stamp * 1e-9:.3f} s)')

    def _wait_frames(self, frames: Sequence[int]) -> None:
        for stamp in frames:
            # The first frames can go out before DDS has matched the camera's best-effort
            # subscriber: nothing is in view yet, so a lost one there changes nothing.
            startup = stamp * 1e-9 - self._start_time < STARTUP_GRACE_S
            with self.inputs.lock:
                if self._wait(functools.partial(self.inputs.detections.__contains__, stamp),
                              1.0 if startup else self.service_timeout):
                    continue
            if not startup:
                raise NodeTimeout(f'no detections for the camera frame at {stamp * 1e-9:.3f}'
                                  ' s (vision_node gone, or its frame lost)')
            self.node.get_logger().warn(f'no detections for the start-up frame at '
                                   f'{stamp * 1e-9:.3f} s (not matched yet); going on')

    def _observe(self, t_ns: int, frames: Optional[Sequence[int]]) -> Observation:
        with self.inputs.lock:
            if frames is None:               # real time: whatever arrived since last time
                frames = sorted(self.inputs.detections)
            dets = [d for f in frames for d in self.inputs.detections.pop(f, [])]
            for f in [f for f in self.inputs.detections if f <= t_ns]:
                del self.inputs.detections[f]
            arms = {name: ArmReading(q, dq, *self.inputs.grip[name][1:])
                    for name, (_, q, dq) in self.inputs.joints.items()}
            bases = {name: BaseReading(odom[1], odom[2])
                     for name, odom in self.inputs.odom.items()}
            belt = [(s * 1e-9, x) for s, x in self.inputs.belt if s <= t_ns]
            self.inputs.belt = [(s, x) for s, x in self.inputs.belt if s > t_ns]
            return Observation(t_ns * 1e-9, arms, bases, dets, belt)

    def final_truth(self, end: float) -> list:
        """The materials' true poses after the run (the score's ground truth)."""
        if self.synchronous:
            try:
                for _ in range(12):                  # let dropped materials settle (0.4 s)
                    self._step(self.steps_per_tick)
            except NodeTimeout:
                pass
        with self.inputs.lock:
            # (Stopped by Ctrl-C or SIGTERM, nothing more comes: the newest there is.)
            self.inputs.lock.wait_for(lambda: bool(self.inputs.markers)
                                and self.inputs.markers[-1][0] * 1e-9 >= end,
                                timeout=5.0 if rclpy.ok() else 0.0)
            return self.inputs.markers[-1][1] if self.inputs.markers else []

