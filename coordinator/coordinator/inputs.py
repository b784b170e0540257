"""What the coordinator hears, as it comes (the executor's threads), for the observer
(observer.py): the arms' joint states, the grips, each base's odometry and laser scans (its
pose in the cell), the vision's detections, the ground truth, the conveyor's encoder and what
the simulator braked."""
from __future__ import annotations

import functools
import threading
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState, LaserScan
from sim_interfaces.msg import GripState, MaterialDetectionArray
from visualization_msgs.msg import MarkerArray

from cell_layout.joint_speeds import driven_past
from cell_layout.layout import CellLayout
from controllers.cell_odometry import odometry_in_cell
from controllers.path_follower import DriveLead, PathFollower
from controllers.scan_localizer import Pose, Scan, ScanLocalizer
from coordinator.pipeline import Detection, Material
from ros_common.geometry import yaw_of
from ros_common.stamps import to_ns
from trial_record.scoring import IdentificationCheck, PeakJointSpeed
from world_description.graph_names import BELT_ENCODER_TOPIC


class Inputs:
    """What the coordinator hears, as it comes (the executor's threads): the arms' joint states
    (and the peaks of their speeds), the grips, the base's odometry in the cell's frame, the
    vision's detections by frame, the ground truth, what the simulator braked. ``lock`` guards
    it all and is notified as each message is taken in. ``now``: the run's clock; ``drive``:
    the base's command, for the path follower run on every odometry message in real time."""

    def __init__(self, node: Node, layout: CellLayout, arms: Mapping[str, Sequence[str]],
                 sim: str, synchronous: bool, drive_lead: float,
                 speed_joints: Dict[str, Dict[str, float]], now: Callable[[], float],
                 drive: Callable[[str, float, float, float], None],
                 localizers: Mapping[str, ScanLocalizer]) -> None:
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
        # Each base's laser localizer, where it has a scanner, and its last scan's stamp.
        self.localizers = dict(localizers)
        self.scan_stamp = {base: -1 for base in self.localizers}
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
        for name in self.localizers:
            node.create_subscription(LaserScan, self.layout.robots[name].topic('scan'),
                                     functools.partial(self._on_scan, name), qos)
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
            if base in self.localizers:
                self.localizers[base].odometry(to_ns(msg.header.stamp), pose)
            self.lock.notify_all()
            pose, world, _ = self.located(base, pose, world)
            follower = self._follower.get(base)
            if follower is not None:
                # Real time: the base controller, on every odometry message. A decision held
                # up by IK calls must not leave the base running on its last command. The
                # command takes effect after the odometry's trip here and its own back: the
                # follower predicts the pose that far ahead.
                status = follower.update(stamp, pose, world[:2], world[2],
                                         lead=self.drive_lead.lead(self.now() - stamp))
                self.drive(base, *status.command)

    def located(self, base: str, pose: Pose, velocity: Pose) -> Tuple[Pose, Pose, str]:
        """A base's pose and velocity in the cell from its odometry's, corrected by its laser
        localizer where it has one, and how (under the lock)."""
        loc = self.localizers.get(base)
        if loc is None:
            return pose, velocity, ''
        return loc.located(pose), loc.located_velocity(velocity), loc.report(pose)

    def _on_scan(self, base: str, msg: LaserScan) -> None:
        scan = Scan(to_ns(msg.header.stamp), msg.angle_min, msg.angle_increment,
                    msg.range_min, msg.range_max, np.asarray(msg.ranges, float))
        with self.lock:
            self.localizers[base].scan(scan)
            self.scan_stamp[base] = scan.stamp_ns
            self.lock.notify_all()

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
