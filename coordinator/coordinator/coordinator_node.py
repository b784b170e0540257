"""The pipeline coordinator node: wires the state machine (pipeline.py) to the node graph.

Inputs: ``/detections`` (vision_node), ``/zu12/joint_states``, ``/youbot/joint_states``,
``/youbot/odom``, the grip states of the Zu 12's cup and the youBot's gripper; for the score
only, the simulator's ground truth ``/cell/materials``. Outputs: arm trajectories, the grip
services, ``/youbot/cmd_vel``, the belt speed (the simulator's ``belt_speed`` parameter), IK
through ``/zu12/solve_ik`` and ``/youbot/solve_ik``; ``~/events`` and ``~/state`` (latched).

Real-time mode follows the simulator's clock (``use_sim_time:=true``). Lock-step mode
(``synchronous:=true``, with the simulator started the same way) keeps its own time, the step
count the simulator reports times the physics step, and needs no ``/clock`` (each message costs
a node about 0.2 ms of CPU in rclpy, 1,800 a trial). It requests every step through
``/sim_node/step`` and, before each decision, waits for the messages of exactly that step
(states stamped with its time, the detections of every camera frame it produced): the same
seed gives the same run. Commands
(topics) go out before the next step request (a service) from the same participant, and the
simulator takes ready subscriptions before ready services; waiting for DDS acknowledgements
instead costs a heartbeat period (seconds) per command.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from sim_interfaces.msg import GripState, MaterialDetectionArray, PipelineEvent, PipelineState
from sim_interfaces.srv import SolveIK, StepSimulation
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import MarkerArray

from controllers.lockstep import CommandCounter, DueGrid
from controllers.path_follower import DriveLead, PathFollower
from controllers.youbot_arm import JOINT_NAMES as YOUBOT_JOINTS
from controllers.zu12_arm import JOINT_NAMES as ZU12_JOINTS
from coordinator.joint_speeds import driven_past, speed_limits
from coordinator.layout import CellLayout, LayoutError, layout_from_world, with_extra_materials
from coordinator.pipeline import (
    Detection,
    Event,
    EventKind,
    NodeTimeout,
    Observation,
    Pipeline,
    Points,
    Settings,
    known,
)
from coordinator.scoring import (
    IdentificationCheck,
    PeakJointSpeed,
    RunTrace,
    build_result,
    destinations,
)
from coordinator.trial_result import TrialResult, code_version
from ros_common.geometry import yaw_of
from ros_common.node_main import run_task
from ros_common.outputs import write_file
from ros_common.params import Param, declare_params
from ros_common.services import NoAnswer, call_and_wait
from ros_common.stamps import duration_from_ns, set_stamp, stamp_from_ns, to_ns
from ros_common.twist_out import TwistOut
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfig, load_world

ARMS = {'zu12': ZU12_JOINTS, 'youbot': YOUBOT_JOINTS}
CAMERA_TOPIC = '/belt_camera/image_raw'
RESEND_S = 1.0            # wall seconds before an unanswered idempotent request is sent again
STARTUP_GRACE_S = 1.0      # simulated seconds in which a lost camera frame is tolerated
STOP_CHECK_S = 0.2         # wall seconds between looks at a stop while waiting
GRIP_SERVICES = {'zu12': '/zu12/suction', 'youbot': '/youbot/gripper/grasp'}


PARAMS = (
    Param('world', PIPELINE_CELL, 'World file of the cell (layout, manifest, belt)'),
    Param('synchronous', False, 'Lock-step: request every simulator step (sim_node '
          'synchronous:=true)'),
    Param('sim_node', '/sim_node', 'The simulator node (its step service and belt_speed '
          'parameter)'),
    Param('control_rate', 30.0, 'Decisions per simulated second', 1.0, 240.0),
    Param('time_step', 1.0 / 240.0, "The simulator's physics step [s] (lock-step batches)",
          1e-4, 0.05),
    Param('state_publish_rate', 30.0, "The simulator's state_publish_rate [Hz] (lock-step "
          'waits for its stamps)', 1.0, 1000.0),
    Param('belt_speed', -1.0, "Belt speed while running [m/s]; -1 takes the world file's",
          -1.0, 1.0),
    Param('pick_x', -0.6, 'The Zu 12 picks materials on the belt downstream of this x [m]',
          -1.0, 1.0),
    Param('max_retries', 1, 'Extra grasp attempts after a missed grasp'),
    Param('drive_speed', Settings.drive_speed, "The path dummy's speed [m/s]", 0.05, 0.8),
    Param('drive_lead', 0.1, 'Real time: how long after an odometry message the base takes the '
          "command that answers it, beyond what the message is late by this node's clock [s "
          'of sim time]; the drive predicts the pose that far ahead', 0.0, 0.3),
    Param('run_timeout', 300.0, 'Longest run [s of sim time]', 10.0, 3600.0),
    Param('idle_timeout', 20.0, 'Belt running with nothing to pick for this long ends the '
          'loading [s]', 1.0, 600.0),
    Param('plan_latency', -1.0, 'Start motions this much after the decision [s of sim time], '
          'and in real time at least this much after they are sent (the message travels while '
          'the simulator runs); -1: 0 in lock-step, 1.0 in real time', -1.0, 5.0),
    Param('service_timeout', 10.0, 'A node that does not answer within this many wall seconds '
          'has failed', 0.5, 120.0),
    Param('result_file', '', 'Write the result (JSON) here at the end'),
    Param('progress_file', '', 'Write the progress (JSON) here once per simulated second'),
    Param('scenario_seed', -1, 'Recorded with the result (the simulator draws the scenario)'),
    Param('extra_materials', RosParameter.Type.STRING_ARRAY, 'Materials in the batch beyond the '
          "world file's, by class (one entry each: materials spawned through the simulator's "
          'spawn_entity, material://<class>)'),
)


class CoordinatorError(RuntimeError):
    pass


def _layout(world: WorldConfig, p: Dict) -> CellLayout:
    """The cell as the world lays it out, at the belt speed the parameters give, with the
    batch's extra materials."""
    try:
        layout = layout_from_world(with_extra_materials(world, p['extra_materials'] or ()))
    except LayoutError as exc:
        raise CoordinatorError(f'{p["world"]}: {exc}') from exc
    if p['belt_speed'] >= 0.0:
        layout = dataclasses.replace(layout, belt_speed=float(p['belt_speed']))
    if layout.belt_speed <= 0.0:
        raise CoordinatorError('the belt speed must be > 0 to bring materials')
    return layout


def _settings(p: Dict) -> Settings:
    latency = float(p['plan_latency'])
    if latency < 0.0:
        latency = 0.0 if p['synchronous'] else 1.0
    settings = Settings(pick_x=float(p['pick_x']), plan_latency=latency,
                        max_retries=int(p['max_retries']), drive_speed=float(p['drive_speed']),
                        run_timeout=float(p['run_timeout']),
                        idle_timeout=float(p['idle_timeout']))
    if settings.max_retries < 0:
        raise CoordinatorError('max_retries must be >= 0')
    return settings


class CoordinatorNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('coordinator_node', **kwargs)
        p = declare_params(self, PARAMS)
        self.world = load_world(resolve_resource(p['world']))
        self.layout = layout = _layout(self.world, p)
        self.settings = _settings(p)
        self.synchronous = bool(p['synchronous'])
        self.rate = float(p['control_rate'])
        self.dt_ns = round(float(p['time_step']) * 1e9)
        # Lock-step: the simulated time of the last step the simulator reported [ns].
        self._lockstep_ns = 0
        self.steps_per_tick = max(1, round(1e9 / self.rate / self.dt_ns))
        state_period = round(1e9 / float(p['state_publish_rate']))
        if self.synchronous and state_period > self.steps_per_tick * self.dt_ns:
            raise CoordinatorError('lock-step needs state_publish_rate >= control_rate')
        cams = [c for c in self.world.cameras if c.name == 'belt_camera']
        self.state_grid = DueGrid(self.dt_ns, state_period)
        self.camera_grid = (DueGrid(self.dt_ns, round(1e9 / cams[0].rate)) if cams else None)
        self.service_timeout = float(p['service_timeout'])
        self.result_file = p['result_file']
        self.progress_file = Path(p['progress_file']) if p['progress_file'] else None
        self.seed = int(p['scenario_seed'])
        self.regions = destinations(layout)
        self._started = time.monotonic()

        self._lock = threading.Condition()
        # arm: (stamp [ns], positions, velocities if the message has them)
        self._joints: Dict[str, Tuple[int, np.ndarray, Optional[np.ndarray]]] = {}
        self._grip: Dict[str, Tuple[int, bool, bool]] = {}      # arm: (stamp, holding, armed)
        # (stamp, the base's pose in the cell (x, y, yaw), its velocity (vx, vy in the cell, wz))
        self._odom: Optional[Tuple[int, Tuple[float, float, float],
                                   Tuple[float, float, float]]] = None
        self._follower: Optional[PathFollower] = None      # real time: the base's drive
        self._drive_lead = DriveLead(float(p['drive_lead']))
        self._detections: Dict[int, List[Detection]] = {}
        self._markers: List[Tuple[int, list]] = []
        self._identifications = IdentificationCheck()
        self._start_time = 0.0
        # Lock-step: the commands of each decision are announced with the next step request,
        # and stamped with the decision's own step time (the plan's), not with a /clock that
        # may lag it.
        self._commands = CommandCounter()
        self._path: List[Tuple[float, float]] = []
        # Every joint with a speed limit in each robot's URDF (arm, gripper, wheels), as the
        # simulator's joint states report it; and what the simulator braked (~/joint_limits).
        self._speed_joints = {arm: speed_limits(self.world, arm) for arm in ARMS}
        self._peak = {arm: PeakJointSpeed(list(limits.values()))
                      for arm, limits in self._speed_joints.items()}
        self._driven_past: List[Dict[str, Any]] = []
        self._connect(p['sim_node'].rstrip('/'))
        self.get_logger().info(
            f'{"lock-step" if self.synchronous else "real-time"} at {self.rate:g} Hz '
            f'({self.steps_per_tick} steps per decision); belt {layout.belt_speed:.3f} m/s, '
            f'{layout.total} materials {layout.manifest}; picks from x = {self.settings.pick_x} m')

    def _connect(self, sim: str) -> None:
        """The node's subscriptions, publishers and clients (``sim``: the simulator's name)."""
        qos = QoSProfile(depth=100)
        for arm, names in ARMS.items():
            self.create_subscription(JointState, f'/{arm}/joint_states',
                                     functools.partial(self._on_joints, arm, names), qos)
            self.create_subscription(GripState, f'{GRIP_SERVICES[arm]}/state',
                                     functools.partial(self._on_grip, arm), qos)
        # Real time: the drive acts on the newest odometry only (one the executor could not
        # take in time is stale); lock-step waits for the stamp of every state.
        self.create_subscription(Odometry, '/youbot/odom', self._on_odom,
                                 qos if self.synchronous else QoSProfile(depth=1))
        self._detections_sub: Optional[Subscription] = self.create_subscription(
            MaterialDetectionArray, '/detections', self._on_detections, qos)
        self.create_subscription(MarkerArray, '/cell/materials', self._on_markers, qos)
        self.create_subscription(
            DiagnosticArray, f'{sim}/joint_limits', self._on_joint_limits,
            QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        reliable = QoSProfile(depth=10)
        self.traj_pubs = {arm: self.create_publisher(
            JointTrajectory, f'/{arm}/arm_controller/joint_trajectory', reliable) for arm in ARMS}
        self._cmd_out = TwistOut(self, '/youbot/cmd_vel', stamped=False)
        self.event_pub = self.create_publisher(PipelineEvent, '~/events', QoSProfile(depth=100))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.state_pub = self.create_publisher(PipelineState, '~/state', latched)
        self.ik = {arm: self.create_client(SolveIK, f'/{arm}/solve_ik') for arm in ARMS}
        self.grips = {arm: self.create_client(SetBool, srv) for arm, srv in GRIP_SERVICES.items()}
        self.step_client = self.create_client(StepSimulation, f'{sim}/step')
        self.param_client = self.create_client(SetParameters, f'{sim}/set_parameters')
        self.param_get_client = self.create_client(GetParameters, f'{sim}/get_parameters')

    # --- inputs -------------------------------------------------------------------------------
    def _on_joints(self, arm: str, names: Sequence[str], msg: JointState) -> None:
        index = {n: i for i, n in enumerate(msg.name)}
        if len(msg.position) != len(msg.name) or not all(n in index for n in names):
            self.get_logger().warn(f'/{arm}/joint_states without the arm joints ignored',
                                   throttle_duration_sec=5.0)
            return
        velocity = (np.array([msg.velocity[index[n]] for n in names])
                    if len(msg.velocity) == len(msg.name) else None)
        limited = self._speed_joints[arm]
        speeds = (np.array([msg.velocity[index[n]] for n in limited])
                  if velocity is not None and all(n in index for n in limited) else None)
        with self._lock:
            self._joints[arm] = (to_ns(msg.header.stamp),
                                 np.array([msg.position[index[n]] for n in names]), velocity)
            if speeds is not None:
                self._peak[arm].update(speeds, to_ns(msg.header.stamp) * 1e-9)
            self._lock.notify_all()

    def _on_joint_limits(self, msg: DiagnosticArray) -> None:
        driven = driven_past(msg)
        with self._lock:
            self._driven_past = driven

    def _on_grip(self, arm: str, msg: GripState) -> None:
        with self._lock:
            self._grip[arm] = (to_ns(msg.header.stamp), bool(msg.holding), bool(msg.armed))
            self._lock.notify_all()

    def _on_odom(self, msg: Odometry) -> None:
        p, q, v = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        yaw = yaw_of(q)
        # The odom frame is the youBot's start pose in the cell (REP-105; no tf2 here).
        hx, hy, hyaw = self.layout.youbot_home
        c, s = math.cos(hyaw), math.sin(hyaw)
        pose = (hx + c * p.x - s * p.y, hy + s * p.x + c * p.y, hyaw + yaw)
        # Odometry's twist is in the child (base) frame; the follower wants it in the world.
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = (c * v.linear.x - s * v.linear.y, s * v.linear.x + c * v.linear.y,
                 v.angular.z)
        stamp = to_ns(msg.header.stamp) * 1e-9
        with self._lock:
            self._odom = (to_ns(msg.header.stamp), pose, world)
            self._lock.notify_all()
            if self._follower is not None:
                # Real time: the base controller, on every odometry message. A decision held
                # up by IK calls must not leave the base running on its last command. The
                # command takes effect after the odometry's trip here and its own back: the
                # follower predicts the pose that far ahead.
                status = self._follower.update(stamp, pose, world[:2], world[2],
                                               lead=self._drive_lead.lead(self.now() - stamp))
                self.drive(*status.command)

    def _on_detections(self, msg: MaterialDetectionArray) -> None:
        stamp = to_ns(msg.header.stamp)
        dets = [Detection(d.id, d.color, np.array([d.position.x, d.position.y, d.position.z]),
                          stamp * 1e-9, d.hits) for d in msg.detections]
        with self._lock:
            self._detections[stamp] = dets
            self._lock.notify_all()

    def _on_markers(self, msg: MarkerArray) -> None:
        if not msg.markers:
            return
        truth = [(m.ns, np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z]))
                 for m in msg.markers]
        with self._lock:
            self._markers.append((to_ns(msg.markers[0].header.stamp), truth))
            del self._markers[:-50]
            self._identifications.truth(self._markers[-1][0], truth)
            self._lock.notify_all()

    # --- the ports the state machine acts through --------------------------------------------
    def now(self) -> float:
        if self.synchronous:
            return self._lockstep_ns * 1e-9
        return self.get_clock().now().nanoseconds * 1e-9

    def _call(self, client, request, what: str, idempotent: bool = True):
        """A service call, waited for. An idempotent one (IK, the grips, the parameters; not a
        step) is sent again every RESEND_S until answered: a reply Fast DDS dropped right after
        discovery must not end the run (ros_common.services.call_and_wait). Stopped (Ctrl-C,
        SIGTERM) while it waits, the run ends as interrupted (_Stopped), not as a node that did
        not answer."""
        if not client.wait_for_service(timeout_sec=self.service_timeout):
            if not rclpy.ok():
                raise _Stopped()
            raise NodeTimeout(f'{client.srv_name} is not available ({what})')
        try:
            return call_and_wait(client, request, self.service_timeout,
                                 resend=RESEND_S if idempotent else 0.0, ok=rclpy.ok)
        except NoAnswer as exc:
            if not rclpy.ok():
                raise _Stopped() from None
            raise NodeTimeout(f'{exc} ({what})') from None

    def solve(self, arm, position, orientation, frame, seed):
        req = SolveIK.Request(execute=False, seed=[float(v) for v in seed])
        req.target.header.frame_id = frame
        p, o = req.target.pose.position, req.target.pose.orientation
        p.x, p.y, p.z = (float(v) for v in position)
        o.x, o.y, o.z, o.w = (float(v) for v in orientation)
        reply = self._call(self.ik[arm], req, 'IK')
        return (np.array(reply.positions), '') if reply.success else (None, reply.message)

    def trajectory(self, arm: str, points: Points, start: float,
                   continuing: bool = False) -> float:
        """Stamped with its absolute start, so that the simulator runs the plan on its own
        clock. Lock-step: the decision's step time, exactly. Real time: the plan (IK calls) may
        have taken longer than its allowance; then the whole motion starts later, by as much,
        rather than with a first segment too short for the joints (returns that delay). A
        motion ``continuing`` the running one is never delayed: the simulator skips its points
        already past and joins it from the running motion."""
        delay = 0.0
        if not self.synchronous and not continuing:
            delay = max(0.0, self.now() + self.settings.plan_latency - start)
        start_ns = round((start + delay) * 1e9)
        msg = JointTrajectory(joint_names=list(ARMS[arm]))
        set_stamp(msg.header.stamp, start_ns)
        for t, q, *rates in points:
            ns = max(1, round((t + delay) * 1e9) - start_ns)
            point = JointTrajectoryPoint(
                positions=[float(v) for v in q],
                time_from_start=duration_from_ns(ns))
            if rates:       # the plan's velocities and accelerations: followed exactly
                point.velocities = [float(v) for v in rates[0]]
                point.accelerations = [float(v) for v in rates[1]]
            msg.points.append(point)
        self.traj_pubs[arm].publish(msg)
        self._commands.sent()
        if delay > 0.0:
            self.get_logger().info(f'{arm} motion starts {delay:.2f} s later than planned '
                                   '(the plan took longer than plan_latency)',
                                   throttle_duration_sec=10.0)
        return delay

    def grip(self, arm: str, on: bool):
        reply = self._call(self.grips[arm], SetBool.Request(data=on), 'grip')
        return reply.success, reply.message

    def belt(self, speed: float) -> Optional[float]:
        value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(speed))
        reply = self._call(self.param_client, SetParameters.Request(
            parameters=[Parameter(name='belt_speed', value=value)]), 'belt speed')
        if not reply.results or not reply.results[0].successful:
            reason = reply.results[0].reason if reply.results else 'no result'
            raise NodeTimeout(f'the simulator refused the belt speed: {reason}')
        # In real time the simulator ran on while the request travelled: the clock seen after
        # the reply bounds when the change took effect (within a /clock hop).
        return None if self.synchronous else self.now()

    def drive(self, vx: float, vy: float, wz: float) -> None:
        self._cmd_out.publish(vx, vy, wz)
        self._commands.sent()

    def follow(self, follower: Optional[PathFollower]) -> bool:
        """Real time: run ``follower`` on every odometry message (the drive's decisions only
        judge it). Lock-step: no; every decision sees every state, and sends the commands."""
        with self._lock:
            self._follower = None if self.synchronous else follower
            return self._follower is not None

    def event(self, e: Event) -> None:
        msg = PipelineEvent(kind=e.kind, robot=e.robot, material_id=e.material, color=e.color,
                            detail=e.detail)
        msg.header.stamp = stamp_from_ns(max(0, round(e.time * 1e9)))
        self.event_pub.publish(msg)
        if e.kind is EventKind.SEEN:
            self._check_identification(e)
        if e.kind is EventKind.LOADING_OVER:
            # No material will be seen again: the detections' reader goes, and with it the
            # vision node's frames (it is lazy) and the simulator's rendering of them.
            self.camera_grid = None            # lock-step: no frame is waited for any more
            self._drop_detections()
        if e.kind is not EventKind.STATE:
            what = f' {e.color} material {e.material}' if e.material >= 0 else ''
            self.get_logger().info(f'[{e.time:7.2f} s] {e.robot or "pipeline"}: {e.kind}{what}'
                                   f'{" - " + e.detail if e.detail else ""}')

    def _drop_detections(self) -> None:
        if self._detections_sub is not None:
            self.destroy_subscription(self._detections_sub)
            self._detections_sub = None

    def _check_identification(self, e: Event) -> None:
        m = self.pipeline.materials.get(e.material)
        with self._lock:
            if m is None or m.detection is None:
                self._identifications.unknown()
            else:
                # The vision's own report, at its frame's time: not where the belt model has
                # carried it since (in real time the coordinator may see a frame late).
                d = m.detection
                self._identifications.seen(round(d.stamp * 1e9), d.position, d.color, m.id)

    # --- the loop -----------------------------------------------------------------------------
    def run(self) -> TrialResult:
        try:
            obs = self._first_observation()
            belt_ran_before = self._belt_runs_at_layout_speed()
        except (NodeTimeout, _Stopped) as exc:
            self.pipeline = Pipeline(self.layout, self, self.settings, self.now())
            self.pipeline.abort(self.now(), *(('interrupted', 'shut down before the start')
                                              if isinstance(exc, _Stopped)
                                              else ('node_timeout', str(exc))))
            return self._report()
        self.pipeline = Pipeline(self.layout, self, self.settings, obs.now, belt_ran_before)
        ticks = 0
        try:
            while not self.pipeline.finished and rclpy.ok():
                self.pipeline.tick(obs)
                self._path.append(obs.youbot_pose[:2])
                ticks += 1
                if ticks % max(1, round(self.rate)) == 0:
                    self._publish_state(obs.now)
                if self.pipeline.finished:
                    break
                obs = self._next_observation(obs)
        except NodeTimeout as exc:
            self.pipeline.abort(self.now(), 'node_timeout', str(exc))
        except _Stopped:
            pass                  # (the simulator and the vision stop with it: nothing comes)
        if not self.pipeline.finished:
            self.pipeline.abort(self.now(), 'interrupted', 'shut down before the end')
        return self._report()

    def _belt_runs_at_layout_speed(self) -> bool:
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

    def _wait_for_graph(self) -> None:
        """Until the nodes the run needs are up: services, the vision node on the camera."""
        clients = list(self.ik.values()) + list(self.grips.values()) + [
            self.param_client, self.param_get_client]
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
            if (self.count_publishers('/detections') > 0
                    and self.count_subscribers(CAMERA_TOPIC) > 0):
                return
            time.sleep(0.05)
        raise NodeTimeout(f'no vision node: nothing publishes /detections or subscribes '
                          f'{CAMERA_TOPIC}')

    def _first_observation(self) -> Observation:
        self._wait_for_graph()
        if self.synchronous:
            before, after = self._step(self.steps_per_tick)
            self._start_time = after * self.dt_ns * 1e-9
            self.state_grid.start_after(after * self.dt_ns)
            if self.camera_grid:
                self.camera_grid.start_after(after * self.dt_ns)
            self._wait_states(after * self.dt_ns, first=True)
            return self._observe(after * self.dt_ns, [])
        end = time.monotonic() + self.service_timeout
        with self._lock:
            # (Woken by each state message; the clock runs with them.)
            if not self._wait(lambda: self._have_states() and self.now() > 0.0,
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
        with self._lock:
            if not self._wait(lambda: bool(self._detections), end - time.monotonic()):
                raise NodeTimeout(f'no detections from the vision node: no camera frame reached '
                                  f'it through {CAMERA_TOPIC}, or its answers did not reach '
                                  f'this node')
        return self._observe(round(self.now() * 1e9), None)

    def _next_observation(self, obs: Observation) -> Observation:
        if not self.synchronous:
            # Until the clock reaches the next decision: woken by each state message (the
            # clock runs with them), and at least every 5 ms (a poll at 1 kHz cost a tenth of
            # a core).
            target = obs.now + 1.0 / self.rate
            end = time.monotonic() + self.service_timeout
            with self._lock:
                while self.now() < target:
                    if time.monotonic() > end:
                        raise NodeTimeout('the simulated clock stopped (simulator gone?)')
                    if not rclpy.ok():
                        raise _Stopped()
                    self._lock.wait(0.005)
            return self._observe(round(self.now() * 1e9), None)
        before, after = self._step(self.steps_per_tick)
        state_due = self.state_grid.advance(before, after)
        frames = self.camera_grid.advance(before, after) if self.camera_grid else []
        if state_due:
            self._wait_states(state_due[-1])
        self._wait_frames(frames)
        return self._observe(after * self.dt_ns, frames)

    def _wait(self, ready: Callable[[], bool], timeout: float) -> bool:
        """Under the lock: until ``ready()`` (True) or ``timeout`` seconds (False), woken by
        what the callbacks deliver; a stop (Ctrl-C, SIGTERM) ends the wait at once (_Stopped):
        the simulator and the vision node stop with this node, and nothing will come."""
        end = time.monotonic() + timeout
        while not ready():
            if not rclpy.ok():
                raise _Stopped()
            left = end - time.monotonic()
            if left <= 0.0:
                return False
            self._lock.wait(min(left, STOP_CHECK_S))
        return True

    def _have_states(self) -> bool:
        """Both arms' joints and grips and the base's odometry have come (under the lock)."""
        return len(self._joints) == 2 and len(self._grip) == 2 and self._odom is not None

    def _wait_states(self, stamp_ns: int, first: bool = False) -> None:
        def ready() -> bool:
            stamps = [j[0] for j in self._joints.values()] + [g[0] for g in self._grip.values()]
            stamps += [self._odom[0]] if self._odom else []
            if len(stamps) < 5:
                return False
            return all(s >= stamp_ns for s in stamps) if first else \
                all(s == stamp_ns for s in stamps)
        with self._lock:
            if not self._wait(ready, self.service_timeout):
                have = {**{f'{a} joints': j[0] for a, j in self._joints.items()},
                        **{f'{a} grip': g[0] for a, g in self._grip.items()},
                        'odom': self._odom[0] if self._odom else None}
                raise NodeTimeout(f'no states from the simulator for t = {stamp_ns * 1e-9:.3f} s'
                                  f' (latest stamps [ns]: {have})')

    def _wait_frames(self, frames: Sequence[int]) -> None:
        for stamp in frames:
            # The first frames can go out before DDS has matched the camera's best-effort
            # subscriber: nothing is in view yet, so a lost one there changes nothing.
            startup = stamp * 1e-9 - self._start_time < STARTUP_GRACE_S
            with self._lock:
                if self._wait(functools.partial(self._detections.__contains__, stamp),
                              1.0 if startup else self.service_timeout):
                    continue
            if not startup:
                raise NodeTimeout(f'no detections for the camera frame at {stamp * 1e-9:.3f}'
                                  ' s (vision_node gone, or its frame lost)')
            self.get_logger().warn(f'no detections for the start-up frame at '
                                   f'{stamp * 1e-9:.3f} s (not matched yet); going on')

    def _observe(self, t_ns: int, frames: Optional[Sequence[int]]) -> Observation:
        with self._lock:
            if frames is None:               # real time: whatever arrived since last time
                frames = sorted(self._detections)
            dets = [d for f in frames for d in self._detections.pop(f, [])]
            for f in [f for f in self._detections if f <= t_ns]:
                del self._detections[f]
            odom = known(self._odom, 'odometry')
            return Observation(
                now=t_ns * 1e-9, zu12_q=self._joints['zu12'][1],
                youbot_q=self._joints['youbot'][1], youbot_pose=odom[1],
                youbot_velocity=odom[2], zu12_holding=self._grip['zu12'][1],
                youbot_holding=self._grip['youbot'][1], detections=dets,
                zu12_armed=self._grip['zu12'][2], youbot_armed=self._grip['youbot'][2],
                zu12_dq=self._joints['zu12'][2], youbot_dq=self._joints['youbot'][2])

    # --- the end ------------------------------------------------------------------------------
    def _final_truth(self) -> list:
        """The materials' true poses after the run (the score's ground truth)."""
        end = self.pipeline.start_time + known(self.pipeline.result, 'the result').completion_time
        if self.synchronous:
            try:
                for _ in range(12):                  # let dropped materials settle (0.4 s)
                    self._step(self.steps_per_tick)
            except NodeTimeout:
                pass
        with self._lock:
            # (Stopped by Ctrl-C or SIGTERM, nothing more comes: the newest there is.)
            self._lock.wait_for(lambda: bool(self._markers)
                                and self._markers[-1][0] * 1e-9 >= end,
                                timeout=5.0 if rclpy.ok() else 0.0)
            return self._markers[-1][1] if self._markers else []

    def _report(self) -> TrialResult:
        result = known(self.pipeline.result, 'the result')
        truth = self._final_truth()
        with self._lock:
            identified = self._identifications.finish()
            trace = RunTrace(
                seed=self.seed, belt_speed=self.layout.belt_speed,
                mode='lock-step' if self.synchronous else 'real-time',
                start=self.pipeline.start_time,
                identification_details=list(self._identifications.details),
                peaks=dict(self._peak),
                joint_names={arm: list(limits) for arm, limits in self._speed_joints.items()},
                driven_past=list(self._driven_past), youbot_path=list(self._path),
                events=list(self.pipeline.events),
                # How old the odometry was when the drive acted on it [s] (simulated time).
                odometry_age=None if self.synchronous else self._drive_lead.summary())
        out = build_result(result, truth, identified, self.regions, trace).with_run(
            code=code_version(), wall_time=round(time.monotonic() - self._started, 2),
            # (Its own CPU time: a trial runner measures the other nodes', which run on.)
            cpu_seconds={'coordinator_node': round(time.process_time(), 2)})
        # The published state and the exit code say what the ground truth says.
        result.status, result.message = out.status, out.message
        self._publish_state(self.now(), out.to_json())
        if self.result_file:
            out.write(Path(self.result_file))
        self.get_logger().info(
            f'run {out.status} in {out.completion_time:.1f} s (sim): identification '
            f'{out.identification_rate:.0%}, grasp {out.grasp_success_rate:.0%} '
            f'({out.grasp_successes}/{out.grasp_attempts}), handling '
            f'{out.handling_success_rate:.0%} ({out.handled_verified}/{out.total})'
            + (f'; {out.message}' if out.message else ''))
        return out

    def _publish_state(self, now: float, result_json: str = '') -> None:
        p = self.pipeline
        tally = p.tally()
        msg = PipelineState(loader_state=p.loader.state.value,
                            transport_state=p.transport.state.value,
                            status=p.result.status if p.result else 'running',
                            total=tally.total, identified=tally.identified, picked=tally.picked,
                            delivered=tally.delivered, missed=tally.missed, failed=tally.failed,
                            elapsed=float(now - p.start_time), result_json=result_json)
        msg.header.stamp = stamp_from_ns(max(0, round(now * 1e9)))
        self.state_pub.publish(msg)
        if self.progress_file is not None:
            try:
                # (Whole or not at all: a campaign's progress line reads it meanwhile.)
                write_file(self.progress_file, json.dumps(dict(
                    sim_time=msg.elapsed, delivered=msg.delivered, total=msg.total,
                    loader=msg.loader_state, transport=msg.transport_state,
                    status=msg.status)).encode())
            except OSError as exc:
                self.get_logger().warn(f'progress file {self.progress_file}: {exc}',
                                       throttle_duration_sec=60.0)


class _Stopped(Exception):
    """The node was stopped (Ctrl-C, SIGTERM) while it waited for the simulator."""


def _run(node: CoordinatorNode) -> int:
    """0 for a completed run, 1 for any other; 0 too for a run stopped by Ctrl-C or SIGTERM
    (its result says 'interrupted'), as a ROS 2 node exits when it is stopped."""
    return 0 if node.run().status in ('completed', 'interrupted') else 1


def _stop_the_robots(node: CoordinatorNode) -> None:
    try:
        node.follow(None)
        node.drive(0.0, 0.0, 0.0)
    except Exception:
        pass


def main(args=None) -> int:
    return run_task(CoordinatorNode, 'coordinator_node', _run,
                    (CoordinatorError, FileNotFoundError, KeyError, ValueError),
                    on_exit=_stop_the_robots, background_spin=True, args=args)


if __name__ == '__main__':
    sys.exit(main())
