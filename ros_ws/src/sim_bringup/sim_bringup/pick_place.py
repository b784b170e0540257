"""Scripted pick and place for the cell: the Zu 12 takes materials that the vision node located
on the moving belt and places them (purple on the ground target, others on the youBot's plate).

Everything goes through the graph: ``/detections`` (vision_node), ``/zu12/solve_ik``
(kinematics_node, arm zu12), ``/zu12/arm_controller/joint_trajectory`` and ``/zu12/suction``
(sim_node), in simulated time. It picks ``count`` materials (or one of each of ``colors``),
then returns the arm to where it started and exits 0; a failed grip or IK ends it with 1.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Dict, List, Optional, Tuple

import numpy as np
import rclpy
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from sim_interfaces.msg import MaterialDetection, MaterialDetectionArray
from sim_interfaces.srv import SolveIK
from std_msgs.msg import Bool
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from controllers.arm_kinematics import motion_duration
from controllers.pick_place import PickTiming, pick_waypoints, place_waypoints, plate_slots
from controllers.zu12_arm import JOINT_NAMES, JOINT_VELOCITY_LIMITS
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world

DOWN = (1.0, 0.0, 0.0, 0.0)          # tool z pointing down (x, y, z, w)
PLATE_HEIGHT_M = 0.0815 + 0.046 + 0.01   # youBot load plate's top above the ground
PLATE_OFFSET_M = -0.159              # plate centre on the youBot's x axis


class PickPlaceError(RuntimeError):
    pass


class PickPlace(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('pick_place', **kwargs)
        ro = ParameterDescriptor
        self.declare_parameter('world', PIPELINE_CELL, ro(
            description='World file: targets, youBot pose, belt and material size',
            read_only=True))
        self.declare_parameter('count', 1, ro(description='Materials to pick', read_only=True))
        self.declare_parameter('colors', [''], ro(
            description='Pick one material of each of these colours instead of count',
            read_only=True))
        self.declare_parameter('pick_x', 0.0, ro(
            description='Where along the belt (world x) to meet a material [m]',
            read_only=True))
        self.declare_parameter('pick_x_max', 0.4, ro(
            description='Furthest along the belt a material may still be met [m]',
            read_only=True))
        self.declare_parameter('lead_time', 2.5, ro(
            description='Plan a pick when the material is this close (in time) to pick_x',
            read_only=True))
        self.declare_parameter('velocity_scaling', 0.6, ro(
            description='Fraction of the joint velocity limits for transfers', read_only=True))
        self.declare_parameter('timeout', 300.0, ro(
            description='Give up after this many seconds of simulated time', read_only=True))
        get = lambda n: self.get_parameter(n).value  # noqa: E731
        self._load_world(get('world'))
        wanted = [c for c in get('colors') if c]
        self.wanted_colors: Optional[List[str]] = wanted or None
        self.count = len(wanted) if wanted else int(get('count'))
        self.pick_x, self.lead = float(get('pick_x')), float(get('lead_time'))
        self.pick_x_max = float(get('pick_x_max'))
        self.scaling, self.timeout = float(get('velocity_scaling')), float(get('timeout'))
        group = ReentrantCallbackGroup()
        qos = QoSProfile(depth=10)
        # Each material's last detection and the stamp of its frame.
        self.latest: Dict[int, Tuple[float, MaterialDetection]] = {}
        self.joints: Optional[np.ndarray] = None
        self._lock = threading.Lock()
        self.create_subscription(MaterialDetectionArray, '/detections', self._on_detections,
                                 qos, callback_group=group)
        self.create_subscription(JointState, '/zu12/joint_states', self._on_joints, qos,
                                 callback_group=group)
        self.tool: Optional[np.ndarray] = None
        self.holding = False
        self.create_subscription(Bool, '/zu12/suction/holding', self._on_holding, qos,
                                 callback_group=group)
        self.create_subscription(PoseStamped, '/zu12/end_effector_pose', self._on_tool, qos,
                                 callback_group=group)
        self.traj_pub = self.create_publisher(JointTrajectory,
                                              '/zu12/arm_controller/joint_trajectory', qos)
        self.ik = self.create_client(SolveIK, '/zu12/solve_ik', callback_group=group)
        self.suction = self.create_client(SetBool, '/zu12/suction', callback_group=group)

    def _load_world(self, uri: str) -> None:
        world = load_world(resolve_resource(uri))
        if world.materials is None or world.conveyor is None:
            raise PickPlaceError(f'{uri} has no conveyor with materials')
        self.size = world.materials.size
        target = [o for o in world.obstacles if o.name == 'ground_target']
        if not target:
            raise PickPlaceError(f'{uri} has no obstacle named ground_target')
        self.ground_target = np.array([target[0].position[0], target[0].position[1], 0.0])
        youbot = world.robot('youbot').pose
        plate = (youbot.x + PLATE_OFFSET_M * np.cos(youbot.yaw),
                 youbot.y + PLATE_OFFSET_M * np.sin(youbot.yaw), PLATE_HEIGHT_M)
        self.slots = plate_slots(plate, youbot.yaw, self.size, 9)
        zu12 = world.robot('zu12').pose
        if (zu12.x, zu12.y, zu12.z, zu12.yaw) != (0.0, 0.0, 0.0, 0.0):
            raise PickPlaceError('this script expects the Zu 12 at the world origin')

    # --- inputs -----------------------------------------------------------------------------
    def _on_detections(self, msg: MaterialDetectionArray) -> None:
        with self._lock:
            stamp = _seconds(msg.header.stamp)
            for d in msg.detections:
                self.latest[d.id] = (stamp, d)

    def _on_joints(self, msg: JointState) -> None:
        index = {n: i for i, n in enumerate(msg.name)}
        if len(msg.position) == len(msg.name) and all(n in index for n in JOINT_NAMES):
            self.joints = np.array([msg.position[index[n]] for n in JOINT_NAMES])

    def _on_holding(self, msg: Bool) -> None:
        self.holding = msg.data

    def _on_tool(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        self.tool = np.array([p.x, p.y, p.z])

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # --- actions ----------------------------------------------------------------------------
    def solve(self, position, seed_note: str, seed=None) -> np.ndarray:
        req = SolveIK.Request(execute=False)
        if seed is not None:
            req.seed = [float(v) for v in seed]
        req.target.header.frame_id = 'world'
        p = req.target.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        o = req.target.pose.orientation
        o.x, o.y, o.z, o.w = DOWN
        reply = self._call(self.ik, req)
        if not reply.success:
            raise PickPlaceError(f'IK for {seed_note} at {np.round(position, 3).tolist()}: '
                                 f'{reply.message}')
        return np.array(reply.positions)

    def solve_path(self, waypoints, note: str, seed) -> list:
        """Joint positions of each waypoint, each seeded with the one before (one branch)."""
        points = []
        for t, p in waypoints:
            seed = self.solve(p, note, seed)
            points.append((t, seed))
        return points

    def send(self, points) -> None:
        """Joint points (absolute sim time, positions) as one trajectory starting now."""
        now = self.now()
        msg = JointTrajectory(joint_names=list(JOINT_NAMES))
        # An absolute start: the belt does not wait for the message to arrive.
        ns = round(now * 1e9)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        for t, q in points:
            ns = max(1, round((t - now) * 1e9))
            msg.points.append(JointTrajectoryPoint(
                positions=[float(v) for v in q],
                time_from_start=Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)))
        self.traj_pub.publish(msg)

    def grip(self, on: bool):
        reply = self._call(self.suction, SetBool.Request(data=on))
        return reply.success, reply.message

    def wait_until(self, t: float) -> None:
        while rclpy.ok() and self.now() < t:
            time.sleep(0.002)

    def _call(self, client, request):
        if not client.wait_for_service(timeout_sec=10.0):
            raise PickPlaceError(f'{client.srv_name} not available')
        future = client.call_async(request)
        end = time.monotonic() + 30.0
        while not future.done():
            if time.monotonic() > end:
                raise PickPlaceError(f'{client.srv_name} did not answer')
            time.sleep(0.002)
        return future.result()

    # --- the task ---------------------------------------------------------------------------
    def run(self) -> int:
        while rclpy.ok() and (self.joints is None or self.now() == 0.0):
            time.sleep(0.01)
        home = self.home = self.joints.copy()
        done, slot, placed, missed = set(), 0, [], []
        start = self.now()
        while len(placed) + len(missed) < self.count:
            for det in self._passed(done):
                done.add(det.id)
                missed.append(det.id)
                self.get_logger().error(f'material {det.id} ({det.color}) passed the pick '
                                        'window unpicked (the arm was busy)')
            if self.now() - start > self.timeout:
                raise PickPlaceError(f'only {len(placed)} of {self.count} materials placed in '
                                     f'{self.timeout} s (missed: {missed})')
            target = self._next(done)
            if target is None:
                time.sleep(0.01)
                continue
            stamp, det, t_contact = target
            place = self.ground_target if det.color == 'purple' else self.slots[slot]
            done.add(det.id)
            if not self._pick_and_place(det, stamp, t_contact, place):
                missed.append(det.id)
                continue
            if det.color != 'purple':
                slot += 1
            placed.append(det.id)
            if self.wanted_colors:
                self.wanted_colors.remove(det.color)
        q = self.joints
        d = motion_duration(q, home, JOINT_VELOCITY_LIMITS, self.scaling, 0.8)
        self.send([(self.now() + d, home)])
        self.wait_until(self.now() + d + 0.3)
        self.get_logger().info(f'done: {len(placed)} materials placed, {len(missed)} missed '
                               f'{missed}; arm back at its start')
        return 0 if not missed else 1

    def _passed(self, done) -> List[MaterialDetection]:
        """Materials (tracked long enough) that are beyond the pick window by now."""
        with self._lock:
            candidates = [(stamp, d) for stamp, d in self.latest.values() if d.id not in done]
        now = self.now()
        return [d for stamp, d in candidates
                if d.hits >= 15 and d.velocity.x > 1e-3
                and (self.wanted_colors is None or d.color in self.wanted_colors)
                and d.position.x + d.velocity.x * (now + self.lead - stamp) > self.pick_x_max]

    def _next(self, done):
        """A material to pick now: its detection and the contact time, or None."""
        with self._lock:
            candidates = [(stamp, d) for stamp, d in self.latest.values() if d.id not in done]
        now = self.now()
        best = None
        for stamp, d in candidates:
            if self.wanted_colors is not None and d.color not in self.wanted_colors:
                continue
            vx = d.velocity.x
            if vx <= 1e-3 or d.hits < 15:
                continue
            t_reach = stamp + (self.pick_x - d.position.x) / vx
            t_contact = max(t_reach, now + self.lead)
            if d.position.x + vx * (t_contact - stamp) > self.pick_x_max:
                continue              # past the pick window before the arm could be there
            if t_reach - now <= self.lead and (best is None or t_contact < best[2]):
                best = (stamp, d, t_contact)
        return best

    def _pick_and_place(self, det: MaterialDetection, stamp: float, t_contact: float,
                        place) -> bool:
        pos = (det.position.x, det.position.y, det.position.z)
        vel = (det.velocity.x, det.velocity.y, 0.0)
        timing = PickTiming()
        # Leave the arm the time its joints need to reach the hover point.
        for _ in range(3):
            waypoints, _ = pick_waypoints(pos, stamp, vel, t_contact, self.size, timing)
            # Seeded from the start pose over the belt: the solution nearest to where the arm
            # is now can be a flip over the top after a place on the other side.
            q_hover = self.solve(waypoints[0][1], f'material {det.id}', self.home)
            needed = motion_duration(self.joints, q_hover, JOINT_VELOCITY_LIMITS, self.scaling,
                                     0.5) + 0.2
            if waypoints[0][0] >= self.now() + needed:
                break
            t_contact = self.now() + needed + timing.descend
        points = self.solve_path(waypoints, f'material {det.id}', q_hover)
        self.send(points)
        # The cup is switched on half-way down: it grips the material when it touches it.
        self.wait_until(waypoints[1][0])
        self.grip(True)
        t_leave = t_contact + timing.dwell
        self.wait_until(t_leave)
        ok = self.holding
        message = 'holding it' if ok else 'nothing held at the end of the dwell'
        self.get_logger().info(f'material {det.id} ({det.color}): {message}')
        if not ok:
            self.grip(False)
            self.get_logger().error(
                f'material {det.id} ({det.color}) missed: {message}; planned contact '
                f'{np.round(waypoints[3][1], 3).tolist()} at {t_contact:.2f} s (now '
                f'{self.now():.2f} s) from the detection at {stamp:.2f} s: '
                f'{np.round(pos, 3).tolist()} moving {np.round(vel, 4).tolist()}; the tool is '
                f'at {np.round(self.tool, 3).tolist() if self.tool is not None else None}')
            self.wait_until(waypoints[-1][0])
            return False
        self.wait_until(waypoints[-1][0])
        above = np.asarray(place) + np.array([0.0, 0.0, self.size + 0.003 + 0.15])
        q_above = self.solve(above, 'the place', points[-1][1])
        d = motion_duration(points[-1][1], q_above, JOINT_VELOCITY_LIMITS, self.scaling, 0.8)
        place_wps, t_release = place_waypoints(self.now() + d, place, self.size, timing)
        self.send(self.solve_path(place_wps, 'the place', points[-1][1]))
        self.wait_until(t_release)
        _, message = self.grip(False)
        self.get_logger().info(f'material {det.id}: {message} at '
                               f'{np.round(place, 3).tolist()}')
        self.wait_until(place_wps[-1][0])
        return True

def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def main(args=None) -> int:
    rclpy.init(args=args)
    try:
        node = PickPlace()
    except (PickPlaceError, rclpy.exceptions.ParameterException, KeyError) as exc:
        rclpy.logging.get_logger('pick_place').fatal(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return 1
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    code = 1
    try:
        code = node.run()
    except PickPlaceError as exc:
        node.get_logger().error(f'pick and place failed: {exc}')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown(timeout_sec=2.0)
        spinner.join(2.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
