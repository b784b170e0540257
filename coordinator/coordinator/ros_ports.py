"""The ports the pipeline's machines act through (coordinator.pipeline.model.Ports), over ROS:
IK through each arm's kinematics node, trajectories, the grip services, the belt speed (the
simulator's parameter), the base's twist, the events. And the one way every service is called
here (``call_service``): a node that does not answer ends the run as a node timeout, a stop
(Ctrl-C, SIGTERM) while waiting ends it as interrupted (``Stopped``)."""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sim_interfaces.msg import PipelineEvent
from sim_interfaces.srv import SolveIK
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from cell_layout.layout import ARM_CONTROLLER, CellLayout
from controllers.lockstep import CommandCounter
from controllers.path_follower import PathFollower
from coordinator.pipeline import Event, EventKind, NodeTimeout, Points, Settings
from ros_common.services import NoAnswer, call_and_wait
from ros_common.stamps import duration_from_ns, set_stamp, stamp_from_ns
from ros_common.twist_out import TwistOut

RESEND_S = 1.0            # wall seconds before an unanswered idempotent request is sent again


class Stopped(Exception):
    """The node was stopped (Ctrl-C, SIGTERM) while it waited for another."""


def call_service(client, request, what: str, timeout: float, idempotent: bool = True):
    """A service call, waited for. An idempotent one (IK, the grips, the parameters; not a
    step) is sent again every RESEND_S until answered: a reply Fast DDS dropped right after
    discovery must not end the run (ros_common.services.call_and_wait). Stopped (Ctrl-C,
    SIGTERM) while it waits, the run ends as interrupted (Stopped), not as a node that did
    not answer."""
    if not client.wait_for_service(timeout_sec=timeout):
        if not rclpy.ok():
            raise Stopped()
        raise NodeTimeout(f'{client.srv_name} is not available ({what})')
    try:
        return call_and_wait(client, request, timeout,
                             resend=RESEND_S if idempotent else 0.0, ok=rclpy.ok)
    except NoAnswer as exc:
        if not rclpy.ok():
            raise Stopped() from None
        raise NodeTimeout(f'{exc} ({what})') from None


class RosPorts:
    """The pipeline's ports on ``node``: its publishers and service clients, made here.
    ``now`` is the run's clock (the observer's); ``set_follower`` hands the base's path
    follower to the observer, which runs it on every odometry message in real time;
    ``on_event`` is told of each event after it is published."""

    def __init__(self, node: Node, layout: CellLayout, sim: str, settings: Settings,
                 synchronous: bool, service_timeout: float, commands: CommandCounter,
                 now: Callable[[], float],
                 set_follower: Callable[[str, Optional[PathFollower]], bool],
                 on_event: Callable[[Event], None]) -> None:
        robots = layout.robots
        self.node, self.settings = node, settings
        self.arms = {name: robot.joints for name, robot in robots.items()}
        self.synchronous, self.service_timeout = synchronous, service_timeout
        self._commands, self.now = commands, now
        self._set_follower, self._on_event = set_follower, on_event
        reliable = QoSProfile(depth=10)
        self.traj_pubs = {arm: node.create_publisher(
            JointTrajectory, robot.topic(f'{ARM_CONTROLLER}/joint_trajectory'), reliable)
            for arm, robot in robots.items()}
        self._cmd_out = {base.name: TwistOut(node, base.topic('cmd_vel'), stamped=False)
                         for base in layout.transports}
        # (Kept for late joiners: a recorder that finds the topic a few seconds into a run, on a
        # busy machine, still records the run's first events, the belt's start among them.)
        self.event_pub = node.create_publisher(
            PipelineEvent, '~/events',
            QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.ik = {arm: node.create_client(SolveIK, robot.topic('solve_ik'))
                   for arm, robot in robots.items()}
        self.grips = {arm: node.create_client(SetBool, robot.grip)
                      for arm, robot in robots.items()}
        self.param_client = node.create_client(SetParameters, f'{sim}/set_parameters')

    def _call(self, client, request, what: str, idempotent: bool = True):
        return call_service(client, request, what, self.service_timeout, idempotent)

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
        msg = JointTrajectory(joint_names=list(self.arms[arm]))
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
            self.node.get_logger().info(f'{arm} motion starts {delay:.2f} s later than planned '
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

    def drive(self, robot: str, vx: float, vy: float, wz: float) -> None:
        self._cmd_out[robot].publish(vx, vy, wz)
        self._commands.sent()

    def follow(self, robot: str, follower: Optional[PathFollower]) -> bool:
        """Real time: run ``follower`` on every odometry message of ``robot`` (the drive's
        decisions only judge it). Lock-step: no; every decision sees every state, and sends
        the commands."""
        return self._set_follower(robot, None if self.synchronous else follower)

    def event(self, e: Event) -> None:
        msg = PipelineEvent(kind=e.kind, robot=e.robot, material_id=e.material, color=e.color,
                            detail=e.detail)
        msg.header.stamp = stamp_from_ns(max(0, round(e.time * 1e9)))
        self.event_pub.publish(msg)
        self._on_event(e)
        if e.kind is not EventKind.STATE:
            what = f' {e.color} material {e.material}' if e.material >= 0 else ''
            self.node.get_logger().info(
                f'[{e.time:7.2f} s] {e.robot or "pipeline"}: {e.kind}{what}'
                f'{" - " + e.detail if e.detail else ""}')
