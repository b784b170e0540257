"""The arm controllers' FollowJointTrajectory action servers, as ros2_controllers' joint
trajectory controller (JTC) offers them: ``<ns>/<controller>/follow_joint_trajectory``.

- A goal must name exactly the controller's joints (JTC without partial goals), have points
  and no multi-DOF part, and valid tolerances; otherwise it is rejected.
- An accepted goal preempts the running one (which ends aborted with INVALID_GOAL, "current
  goal canceled: preempted by a new goal", as JTC reports it; an action goal may end canceled
  only at its client's request), and is then validated as a topic trajectory is; an invalid
  one aborts with INVALID_GOAL and the reason.
- While it runs: feedback at the state rate (desired, actual, error); path tolerances are
  checked against the feedback, and a violation aborts the goal and holds the arm where it is.
  (A trajectory arriving on the topic preempts a running goal the same way.)
- After the trajectory's end: success once within the goal tolerances; GOAL_TOLERANCE_VIOLATED
  if still out of them ``goal_time_tolerance`` later (0: no limit, as JTC).
- A cancel holds the arm where it is and ends the goal canceled.
- ``~/reset`` and ``~/pause`` end every running goal, aborted with INVALID_GOAL and the reason
  (the arm back at its start pose, or held where it is); a robot's fault ends its goals with
  PATH_TOLERANCE_VIOLATED. A goal never outlives the motion it asked for.

The judging is ``controllers.trajectory_goal`` (no ROS). The server runs on the node's
executor: a goal's execution is a coroutine that awaits its outcome, which the state updates
set (no thread waits).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Dict, List, Tuple

import numpy as np
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.node import Node
from rclpy.task import Future

from controllers.trajectory_goal import (
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    GoalMonitor,
    Outcome,
    Tolerance,
    check_tolerances,
)
from ros_common.stamps import stamp_from_ns, to_seconds
from sim_bridge.messages import topic, trajectory_feedback, trajectory_request


@dataclass
class _Running:
    handle: ServerGoalHandle
    monitor: GoalMonitor
    outcome: Future
    canceled: bool = False      # (by the client's cancel request)


def _tolerances(msgs) -> List[Tuple[str, Tolerance]]:
    return [(t.name, Tolerance(t.position, t.velocity, t.acceleration)) for t in msgs]


def merged_path_tolerance(joint_names, defaults, goal) -> np.ndarray:
    """The position path tolerance per joint for a goal, as JTC merges them: a goal's value
    > 0 replaces the controller's default for that joint, -1 erases it (not checked), 0 or a
    joint left out keeps it."""
    merged = np.array(defaults, float)
    for name, tol in goal:
        i = list(joint_names).index(name)
        if tol.position > 0.0:
            merged[i] = tol.position
        elif tol.position == -1.0:
            merged[i] = 0.0
    return merged


class TrajectoryActions:
    """One action server per arm controller of the world."""

    def __init__(self, node: Node, world, runner) -> None:
        self._node, self._world, self._runner = node, world, runner
        self._running: Dict[Tuple[str, str], _Running] = {}
        self.servers = []
        for name, robot in world.robots.items():
            for controller in robot.controllers:
                key = (name, controller)
                self.servers.append(ActionServer(
                    node, FollowJointTrajectory,
                    topic(robot.config.namespace, f'{controller}/follow_joint_trajectory'),
                    execute_callback=functools.partial(self._execute, key),
                    goal_callback=functools.partial(self._on_goal, key),
                    handle_accepted_callback=functools.partial(self._on_accepted, key),
                    cancel_callback=lambda _request: CancelResponse.ACCEPT))

    # --- the goal's life ---------------------------------------------------------------------
    def _on_goal(self, key: Tuple[str, str], goal) -> GoalResponse:
        why = self._invalid(key, goal)
        if why:
            self._node.get_logger().error(f'{key[0]}/{key[1]}: goal rejected: {why}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _invalid(self, key: Tuple[str, str], goal) -> str:
        joints = self._group(key).joint_names
        names = list(goal.trajectory.joint_names)
        if sorted(names) != sorted(joints) or len(set(names)) != len(names):
            return f'the goal names joints {names}; this controller has {list(joints)}'
        if not goal.trajectory.points:
            return 'the trajectory has no points'
        if goal.multi_dof_trajectory.points or goal.multi_dof_trajectory.joint_names:
            return 'multi-DOF trajectories are not supported'
        for what, tolerances in (('path', goal.path_tolerance), ('goal', goal.goal_tolerance)):
            why = check_tolerances(joints, _tolerances(tolerances))
            if why:
                return f'{what} tolerances: {why}'
        if goal.component_path_tolerance or goal.component_goal_tolerance:
            return 'component tolerances are for multi-DOF joints, which this controller has not'
        goal_time = to_seconds(goal.goal_time_tolerance)
        if not goal_time >= 0.0:
            return f'goal_time_tolerance must be >= 0, got {goal_time}'
        return ''

    def _on_accepted(self, key: Tuple[str, str], handle) -> None:
        self.preempt(key, 'preempted by a new goal')
        handle.execute()

    async def _execute(self, key: Tuple[str, str], handle):
        goal = handle.request
        group = self._group(key)
        result = self._runner.set_trajectory(
            *key, trajectory_request(goal.trajectory),
            path_tolerance=merged_path_tolerance(group.joint_names, group.path_tolerance,
                                                 _tolerances(goal.path_tolerance)))
        if not result.accepted:
            self._node.get_logger().error(f'{key[0]}/{key[1]}: goal aborted: {result.reason}')
            handle.abort()
            return _result(Outcome(INVALID_GOAL, result.reason))
        self._node.get_logger().info(
            f'{key[0]}/{key[1]}: following a goal of {len(goal.trajectory.points)} points')
        running = _Running(handle, GoalMonitor(
            group.joint_names, group.follower.end_time, _tolerances(goal.path_tolerance),
            _tolerances(goal.goal_tolerance), to_seconds(goal.goal_time_tolerance)), Future())
        self._running[key] = running
        outcome: Outcome = await running.outcome
        if self._running.get(key) is running:
            del self._running[key]
        if running.canceled:
            handle.canceled()
        elif outcome.succeeded:
            handle.succeed()
        else:
            self._node.get_logger().error(f'{key[0]}/{key[1]}: goal aborted: {outcome.message}')
            handle.abort()
        return _result(outcome)

    # --- called by the simulator ------------------------------------------------------------
    def preempt(self, key: Tuple[str, str], why: str) -> None:
        """End the running goal of a controller, canceled (a new goal, or a topic command
        took over)."""
        running = self._running.pop(key, None)
        if running is not None and not running.outcome.done():
            # (An action goal may end canceled only after the client asked: a preempted goal
            # ends aborted, with JTC's INVALID_GOAL code and the reason.)
            running.outcome.set_result(Outcome(INVALID_GOAL, f'current goal canceled: {why}'))

    def abort(self, key: Tuple[str, str], why: str) -> None:
        """End the running goal of a controller with PATH_TOLERANCE_VIOLATED: the simulator
        stopped its trajectory (a joint lagged its reference, or the robot faulted)."""
        running = self._running.pop(key, None)
        if running is not None and not running.outcome.done():
            running.outcome.set_result(Outcome(PATH_TOLERANCE_VIOLATED, why))

    def abort_all(self, why: str, hold: bool) -> List[str]:
        """End every running goal, aborted with INVALID_GOAL and ``why`` (the simulation was
        reset or paused under it; JTC ends a goal so when it is deactivated); with ``hold``
        the arm stays where it is. Returns the controllers whose goal ended."""
        ended = []
        for key in list(self._running):
            running = self._running.pop(key)
            if running.outcome.done():
                continue
            if hold:
                self._group(key).hold_current()
            running.outcome.set_result(Outcome(INVALID_GOAL, why))
            ended.append(f'{key[0]}/{key[1]}')
        return ended

    def on_state(self, robot: str, now: float) -> None:
        """Judge and report the robot's running goals (at the state rate)."""
        for key in [k for k in self._running if k[0] == robot]:
            running = self._running[key]
            group = self._group(key)
            reference = group.desired
            position, velocity = group.actual()
            if running.handle.is_cancel_requested:
                group.hold_current()
                running.canceled = True
                del self._running[key]
                running.outcome.set_result(Outcome(SUCCESSFUL, 'canceled'))
                continue
            running.handle.publish_feedback(trajectory_feedback(
                stamp_from_ns(self._world.sim_time_ns), group.joint_names, reference, position,
                velocity))
            outcome = running.monitor.check(now, reference.positions, reference.velocities,
                                            position, velocity)
            if outcome is None:
                continue
            if not outcome.succeeded:
                contacts = self._world.contacts_of(group)
                if contacts:                # (why the arm is off: what it pushes against)
                    outcome = Outcome(outcome.code,
                                      f'{outcome.message}; in contact: {", ".join(contacts)}')
                group.hold_current()        # (JTC holds position when it aborts)
            del self._running[key]
            running.outcome.set_result(outcome)

    def _group(self, key: Tuple[str, str]):
        return self._world.robots[key[0]].controllers[key[1]]


def _result(outcome: Outcome):
    return FollowJointTrajectory.Result(error_code=outcome.code, error_string=outcome.message)
