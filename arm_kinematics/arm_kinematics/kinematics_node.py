"""Kinematics node of an arm: publishes the tool pose from joint_states and answers IK.

Any arm a world names: ``arm`` is the robot's name in ``world``, whose entry gives its URDF, the
joints of its ``arm_controller`` and its grip tool (the tool frame: a link and an offset). The
model registry (controllers/arm_registry.py) solves it with an analytic fast path where one is
registered for the URDF's chain (the Zu 12's, the youBot arm's), else with the generic solver
(pinocchio, damped least squares within the joint limits).

Run it in the robot's namespace (``--ros-args -r __ns:=/youbot``):
- subscribes ``joint_states``; publishes ``end_effector_pose`` (PoseStamped, in base_link);
- service ``solve_ik`` (sim_interfaces/SolveIK): a target pose in, the joint positions out, and
  with ``execute`` a trajectory sent to ``arm_controller/joint_trajectory``;
- topic ``goal_pose`` (PoseStamped): solve and execute; every outcome goes out on ``ik_status``
  (diagnostic_msgs/DiagnosticStatus), failures are logged as errors.
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Optional, Tuple

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from sim_interfaces.srv import SolveIK
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from cell_layout.arm_models import ArmModelError, arm_model, solver_of
from controllers.arm_model import plan_ik
from controllers.transforms import matrix_to_quaternion, pose_matrix
from ros_common.node_main import run_node
from ros_common.params import Param, declare_params
from ros_common.services import SERVICE_QOS
from ros_common.stamps import duration_from_seconds
from world_description.errors import WorldConfigError
from world_description.resources import ResourceError, resolve_resource
from world_description.world_loading import load_world
from world_description.world_schema import SuctionConfig

PAPER_WORLD = 'package://world_description/worlds/pipeline_cell.yaml'

PARAMS = (
    Param('world', PAPER_WORLD, 'The world file that describes the arm'),
    Param('arm', 'youbot', "The arm's robot name in the world"),
    Param('tool_frame', '', "Link whose pose is published and solved for; empty: the world's "
          'grip tool (its link and offset)'),
    Param('frame_prefix', '', "Prefix of the robot's frame names (as in the world file)"),
    Param('velocity_scaling', 0.5, 'Default fraction of the joint velocity limits for IK '
          'motions', 0.01, 1.0),
    Param('min_duration', 0.5, 'Shortest IK motion [s]', 0.01, 60.0),
    Param('trajectory_topic', 'arm_controller/joint_trajectory', 'Where IK motions go '
          '(relative: in the node namespace)'),
    Param('track_joint_states', True, 'Take joint_states: the current position (the default '
          'IK seed, the start of a motion that execute plans) and end_effector_pose. false: '
          'serve only requests that give a seed and plan no motion (a client that knows the '
          "arm's state, as the pipeline coordinator; 30 messages a second less to take)"),
)


class KinematicsConfigError(ValueError):
    """Parameters the node cannot run with."""


class KinematicsNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('kinematics_node', **kwargs)
        p = declare_params(self, PARAMS)
        arm = p['arm']
        self._kin, solver = _kinematics(p['world'], arm, p['tool_frame'])
        tool = p['tool_frame'] or 'its grip tool'
        self._prefix = p['frame_prefix']
        self._motion_defaults = (p['velocity_scaling'], p['min_duration'])
        self._positions: Optional[np.ndarray] = None
        reliable = QoSProfile(depth=10)
        self._pose_pub = self.create_publisher(PoseStamped, 'end_effector_pose', reliable)
        traj_topic = p['trajectory_topic']
        self._traj_pub = self.create_publisher(JointTrajectory, traj_topic, reliable)
        self._status_pub = self.create_publisher(DiagnosticStatus, 'ik_status', reliable)
        self._tracking = bool(p['track_joint_states'])
        if self._tracking:
            self.create_subscription(JointState, 'joint_states', self._on_joint_states,
                                     reliable)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal_pose, reliable)
        self.create_service(SolveIK, 'solve_ik', self._on_solve_ik, qos_profile=SERVICE_QOS)
        self.get_logger().info(
            f'{arm} arm ({solver}), tool frame {self._prefix}{tool}: publishing '
            f'{self._pose_pub.topic_name}; IK on {self.resolve_service_name("solve_ik")} and '
            f'{self.resolve_topic_name("goal_pose")}; motions to {self._traj_pub.topic_name}')

    # --- joint states -> end-effector pose ----------------------------------------------------
    def _on_joint_states(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name):
            self.get_logger().warn(f'joint_states with {len(msg.name)} names and '
                                   f'{len(msg.position)} positions ignored',
                                   throttle_duration_sec=5.0)
            return
        index = {name: i for i, name in enumerate(msg.name)}
        if not all(name in index for name in self._kin.joint_names):
            return
        q = np.array([msg.position[index[name]] for name in self._kin.joint_names])
        if not np.all(np.isfinite(q)):
            self.get_logger().warn('joint_states with non-finite arm positions ignored',
                                   throttle_duration_sec=5.0)
            return
        self._positions = q
        if self._pose_pub.get_subscription_count() == 0:
            return              # (nobody reads the pose: no FK, no message)
        out = PoseStamped()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = self._prefix + 'base_link'
        _fill_pose(out, self._kin.fk(q))
        self._pose_pub.publish(out)

    # --- IK -----------------------------------------------------------------------------------
    def _on_solve_ik(self, request, response):
        ok, message, positions, errors, trajectory = self._solve(
            request.target, request.execute, request.duration, request.velocity_scaling,
            list(request.seed))
        response.success, response.message = ok, message
        response.joint_names = list(self._kin.joint_names)
        if positions is not None:
            response.positions = positions.tolist()
            response.position_error, response.rotation_error = errors
        if trajectory is not None:
            response.trajectory = trajectory
        return response

    def _on_goal_pose(self, msg: PoseStamped) -> None:
        ok, message, positions, _, _ = self._solve(msg, True, 0.0, 0.0)
        if not ok:
            # (Nobody waits for an answer here: the reason goes to the log and /diagnostics.)
            self.get_logger().warn(f'goal_pose: IK failed: {message}')
        status = DiagnosticStatus(level=DiagnosticStatus.OK if ok else DiagnosticStatus.ERROR,
                                  name=self.get_fully_qualified_name() + ': goal_pose',
                                  message=message, hardware_id=self._prefix + 'arm')
        if positions is not None:
            status.values = [KeyValue(key=n, value=f'{v:.6f}')
                             for n, v in zip(self._kin.joint_names, positions)]
        self._status_pub.publish(status)

    def _solve(self, target: PoseStamped, execute: bool, duration: float,
               scaling: float, seed: Optional[list] = None
               ) -> Tuple[bool, str, Optional[np.ndarray], tuple, Optional[JointTrajectory]]:
        p, o = target.pose.position, target.pose.orientation
        if not self._tracking and (execute or not seed):
            return self._fail('joint_states are not taken (track_joint_states is false): give '
                              'a seed, and execute=false' + ('' if seed else ' (no seed given)'))
        try:
            pose = pose_matrix((p.x, p.y, p.z), (o.x, o.y, o.z, o.w))
            pose = self._kin.in_base_link(target.header.frame_id, pose, self._prefix)
        except (KeyError, ValueError) as exc:
            return self._fail(f'bad target: {exc.args[0]}')
        plan = plan_ik(self._kin, pose, execute, duration, scaling, self._positions, seed,
                       *self._motion_defaults)
        if not plan.success:
            return self._fail(plan.message)
        if plan.duration is None or plan.positions is None:
            return True, plan.message, plan.positions, plan.errors, None
        trajectory = _trajectory(self._kin.joint_names, plan.positions, plan.duration)
        self._traj_pub.publish(trajectory)
        self.get_logger().info(f'IK: {plan.message}')
        return True, plan.message, plan.positions, plan.errors, trajectory

    def _fail(self, message: str):
        # A failure is an answer (the reply, or the goal_pose warning, carries it): a caller
        # that probes reachability gets many, which are no error of this node.
        self.get_logger().debug(f'IK failed: {message}')
        return False, message, None, (float('inf'), float('inf')), None


def _kinematics(world: str, arm: str, tool_frame: str):
    """The arm's kinematics and its solver's name, from the world; a KinematicsConfigError
    (one line) for an arm the world does not describe."""
    try:
        config = load_world(resolve_resource(world))
    except (WorldConfigError, ResourceError, OSError) as exc:
        raise KinematicsConfigError(f'world {world}: {exc}') from None
    names = [r.name for r in config.robots]
    if arm not in names:
        raise KinematicsConfigError(f'arm "{arm}" unknown: the world {world} has {names}')
    robot = config.robot(arm)
    if tool_frame:
        robot = replace(robot, suction=SuctionConfig(tool_frame))
    base_dir = Path(config.source).parent if config.source else None
    try:
        model = arm_model(robot, base_dir)
    except ArmModelError as exc:
        raise KinematicsConfigError(str(exc)) from None
    return model.kinematics, solver_of(model.spec)


def _fill_pose(msg: PoseStamped, pose: np.ndarray) -> None:
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v)
                                                                     for v in pose[:3, 3])
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(pose[:3, :3])


def _trajectory(names, positions: np.ndarray, duration: float) -> JointTrajectory:
    """One point at rest at ``duration``: the controller interpolates from where it is."""
    point = JointTrajectoryPoint(positions=positions.tolist(),
                                 velocities=[0.0] * len(positions))
    point.time_from_start = duration_from_seconds(duration)
    return JointTrajectory(joint_names=list(names), points=[point])


def main(args=None) -> int:
    return run_node(KinematicsNode, 'kinematics_node', (KinematicsConfigError,), args=args)


if __name__ == '__main__':
    sys.exit(main())
