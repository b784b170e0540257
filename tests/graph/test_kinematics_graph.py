"""The kinematics node over DDS, with the simulator in this process so that the test can read
PyBullet's ground truth: an IK request moves the simulated arm's gripper to the target."""
import threading

import numpy as np
import pytest
import rclpy
from control_msgs.msg import JointTrajectoryControllerState
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sim_interfaces.srv import SolveIK

from controllers.transforms import matrix_to_quaternion, rotation_angle
from controllers.youbot_kinematics import YoubotKinematics
from helpers import Probe, latest_stamp, moving, wait_for, wait_for_stamp

RTF = 2.0


class InProcessSim:
    """sim_node in this process, so the test can read PyBullet's ground truth."""

    def __init__(self):
        from sim_bridge.sim_node import SimNode
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = SimNode(context=self.context, parameter_overrides=[
            Parameter('world', value='package://world_description/worlds/youbot.yaml'),
            Parameter('real_time_factor', value=RTF), Parameter('rtf_log_period', value=0.0)])
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self._running = True
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        while self._running:
            with self.lock:
                self.executor.spin_once(timeout_sec=0.01)

    def tcp_in_base_link(self):
        with self.lock:
            return self.node._world.robots['youbot'].link_pose_in_base('gripper_tcp')

    def close(self):
        self._running = False
        self.thread.join(5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _ik_request(target, **fields) -> SolveIK.Request:
    """A SolveIK request for the 4x4 pose ``target`` in base_link."""
    request = SolveIK.Request(**fields)
    request.target.header.frame_id = 'base_link'
    pos = request.target.pose.position
    pos.x, pos.y, pos.z = (float(v) for v in target[:3, 3])
    o = request.target.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(target[:3, :3])
    return request


def test_kinematics_node_moves_the_simulated_arm_to_an_ik_target(start_node):
    sim = InProcessSim()
    probe = Probe()
    try:
        kin = start_node('kinematics_node', '-r', '__ns:=/youbot', '-p', 'use_sim_time:=true')
        poses = probe.collect(PoseStamped, '/youbot/end_effector_pose')
        states = probe.collect(JointTrajectoryControllerState,
                               '/youbot/arm_controller/controller_state')
        wait_for(lambda: poses and states, 30.0, what='the end-effector pose')
        # The published pose is PyBullet's at the candle start.
        p = poses[-1][1].pose.position
        assert (p.x, p.y, p.z) == pytest.approx(sim.tcp_in_base_link()[:3, 3], abs=1e-3)
        # A reachable target in front of the robot, gripper pointing down and forward.
        target = YoubotKinematics().fk([0.6, 0.9, 0.7, 0.9, -0.4])
        assert target[2, 3] > 0.0
        request = _ik_request(target, execute=True)
        pos = request.target.pose.position
        reply = probe.call(SolveIK, '/youbot/solve_ik', request, timeout=20.0)
        assert reply.success, reply.message
        assert reply.position_error < 1e-4 and len(reply.trajectory.points) == 1
        wait_for(lambda: moving(states[-1][1]), 10.0, what='the motion to start')
        wait_for(lambda: not moving(states[-1][1]), 30.0, what='the motion to end')
        wait_for(lambda: np.linalg.norm(sim.tcp_in_base_link()[:3, 3] - target[:3, 3]) < 0.005,
                 10.0, what='the tool at the target')
        reached = sim.tcp_in_base_link()
        assert rotation_angle(reached[:3, :3].T @ target[:3, :3]) < 0.01
        # An unreachable target (the same arm plane, four times as far): a clear failure.
        pos.x = 0.167 + 4 * (target[0, 3] - 0.167)
        pos.y = 4 * target[1, 3]
        reply = probe.call(SolveIK, '/youbot/solve_ik', request, timeout=20.0)
        assert not reply.success and 'out of reach' in reply.message
        request.target.header.frame_id = 'odom'
        reply = probe.call(SolveIK, '/youbot/solve_ik', request, timeout=20.0)
        assert not reply.success and 'unknown frame "odom"' in reply.message
        # (Answers, not errors of the node: a caller probing reachability gets many.)
        assert '[ERROR]' not in kin.output() and kin.alive()
        # Half a second of simulated time later, the arm still holds the target.
        wait_for_stamp(states, latest_stamp(states) + 0.5, what='0.5 s of simulated time')
        assert not moving(states[-1][1])
        assert np.linalg.norm(sim.tcp_in_base_link()[:3, 3] - target[:3, 3]) < 0.005
    finally:
        probe.close()
        sim.close()


def test_an_ik_server_that_takes_no_joint_states_serves_seeded_requests(start_node):
    """track_joint_states:=false (the trials' IK servers): no joint_states reader; a seeded
    request that plans no motion is solved as with them, and a request that needs the arm's
    state (no seed, or execute) is refused with the reason."""
    probe = Probe()
    try:
        kin = start_node('kinematics_node', '-r', '__ns:=/youbot', '-p',
                         'track_joint_states:=false')
        target = YoubotKinematics().fk([0.6, 0.9, 0.7, 0.9, -0.4])
        request = _ik_request(target, execute=False, seed=[0.5, 0.8, 0.8, 0.8, -0.3])
        reply = probe.call(SolveIK, '/youbot/solve_ik', request, timeout=20.0)
        assert reply.success and reply.position_error < 1e-4, reply.message
        assert np.allclose(YoubotKinematics().fk(reply.positions)[:3, 3], target[:3, 3],
                           atol=1e-4)
        # (Its readers are known here once goal_pose's is: they were made together.)
        wait_for(lambda: probe.node.count_subscribers('/youbot/goal_pose') == 1, 10.0,
                 what="the node's goal_pose reader")
        assert probe.node.count_subscribers('/youbot/joint_states') == 0
        for execute, seed in ((False, []), (True, list(request.seed))):
            request.execute, request.seed = execute, seed
            reply = probe.call(SolveIK, '/youbot/solve_ik', request, timeout=20.0)
            assert not reply.success and 'track_joint_states is false' in reply.message
        assert kin.alive()
    finally:
        probe.close()
