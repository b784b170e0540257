"""ROS 2 node around SimRunner: the simulator's topics and services.

The node is an adapter. What it does lives elsewhere: the world and its physics in
``world.py``, advancing it and judging commands in ``runner.py`` (no ROS), how time advances
(real time, pause, lock-step ``~/step``) in ``stepping.py``, what a step produces, published,
in ``step_outputs.py``, what the node says about its inputs and joints in
``node_diagnostics.py``, the trajectory actions in ``trajectory_action.py``, the messages in
``messages.py`` and the parameters in ``parameters.py``. Here: the subscriptions and services
that take commands, and the node's start and end.
"""
from __future__ import annotations

import functools
import re
import sys
import threading

from geometry_msgs.msg import Twist, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory

from ros_common.node_main import run_node
from ros_common.params import declare_params
from ros_common.services import SERVICE_QOS
from sim_bridge import messages
from sim_bridge.entities import Entities
from sim_bridge.hold_watch import HoldWatch
from sim_bridge.messages import topic
from sim_bridge.node_diagnostics import NodeDiagnostics
from sim_bridge.parameters import PARAMS, SimConfigError, check_params
from sim_bridge.runner import ZERO, DriveLimits, SimRunner
from sim_bridge.sim_api import SimulationInterfaces
from sim_bridge.step_outputs import OutputOptions, StepOutputs
from sim_bridge.stepping import Stepping
from sim_bridge.trajectory_action import TrajectoryActions
from sim_bridge.world import SimWorld, WorldError
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world

RELIABILITIES = {'reliable': ReliabilityPolicy.RELIABLE,
                 'best_effort': ReliabilityPolicy.BEST_EFFORT}
# Wall seconds between a quitting request's reply and the end of the node.
QUIT_DELAY_S = 1.0
# Numbers in a rejection's reason: two reasons that differ only in them are of one kind.
_NUMBERS = re.compile(r'-?\d[\d.e+-]*|nan|inf')


class SimNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('sim_node', **kwargs)
        p = declare_params(self, PARAMS)
        check_params(p)
        world_path = resolve_resource(p['world'])
        seed = p['scenario_seed'] if p['scenario_seed'] >= 0 else None
        self._world = SimWorld(load_world(world_path), time_step=p['time_step'], gui=p['gui'],
                               scenario_seed=seed)
        if self._world.conveyor is not None and p['belt_speed'] >= 0.0:
            self._world.conveyor.speed = p['belt_speed']
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._runner = SimRunner(self._world, DriveLimits(
            p['max_speed'], p['max_turn'], p['cmd_vel_timeout'],
            p['linear.x.max_acceleration'] or None, p['angular.z.max_acceleration'] or None),
            p['state_publish_rate'], p['materials_publish_rate'], p['clock_publish_rate'])
        self._diagnostics = NodeDiagnostics(self, list(self._world.robots),
                                            lambda: self._world.sim_time_ns)
        self._actions = TrajectoryActions(self, self._world, self._runner)
        self._outputs = StepOutputs(
            self, self._world, self._runner, self._actions, self._diagnostics,
            OutputOptions(p['publish_link_tf'], p['jpeg_quality'],
                          RELIABILITIES[p['camera_reliability']]))
        for name in self._world.robots:
            self._subscribe(name, p['use_stamped_vel'])
        self.create_service(Trigger, '~/reset', self._on_reset, qos_profile=SERVICE_QOS)
        self._stepping = Stepping(
            self, self._runner, self._outputs, self._actions, synchronous=p['synchronous'],
            time_step=p['time_step'], real_time_factor=p['real_time_factor'],
            max_steps_per_tick=p['max_steps_per_tick'], step_chunk=p['step_chunk'],
            rtf_log_period=p['rtf_log_period'])
        # The standard simulator interfaces (sim_api.py); quitting through them ends the run.
        self.exit_request, self.exit_code = threading.Event(), 0
        self._entities = Entities(self._world, lambda: self._world.sim_time)
        self._sim_api = SimulationInterfaces(self, self._stepping, self._entities,
                                             self._reset_world, self._quit_soon,
                                             p['world'], lambda: self._world.sim_time_ns)
        self._runner.tick_clock(self._outputs)
        for name in self._world.robots:
            self._outputs.on_state(name, self._world.sim_time_ns)
        limits = ', '.join(f'{name} {self._runner.shown(name, guard.limits)}'
                           for name, guard in self._runner.guards.items()) or 'none'
        controllers = ', '.join(f'{name}/{c}' for name, robot in self._world.robots.items()
                                for c in robot.controllers) or 'none'
        self.get_logger().info(
            f'world {world_path} with robots {sorted(self._world.robots)} and cameras '
            f'{[c.config.name for c in self._world.cameras]}; dt {p["time_step"]:.6f} s, '
            f'{self._stepping.describe()}; cmd_vel limits {limits}, '
            f'cmd_vel timeout {p["cmd_vel_timeout"]} s; trajectory controllers {controllers}')

    def _subscribe(self, name: str, stamped_vel: bool) -> None:
        """A robot's commands: its suction service, its cmd_vel (a driven base) and each of
        its controllers' trajectory topic."""
        robot = self._world.robots[name]
        ns, suction = robot.config.namespace, robot.config.suction
        if name in self._world.suctions and suction is not None:
            self.create_service(SetBool, topic(ns, suction.service),
                                functools.partial(self._on_suction, name),
                                qos_profile=SERVICE_QOS)
        if name in self._runner.guards:
            self.create_subscription(TwistStamped if stamped_vel else Twist,
                                     topic(ns, 'cmd_vel'),
                                     functools.partial(self._on_cmd_vel, name), 10)
        for controller in robot.controllers:
            self.create_subscription(
                JointTrajectory, topic(ns, f'{controller}/joint_trajectory'),
                functools.partial(self._on_trajectory, name, controller), 10)

    # --- subscriptions and services -----------------------------------------------------------
    def _on_cmd_vel(self, robot: str, msg) -> None:
        self._stepping.command_arrived()
        verdict = self._runner.judge_twist(robot, messages.twist_values(msg),
                                           messages.twist_stamp(msg))
        for kind, text in verdict.notes:
            self._diagnostics.warn((robot, 'cmd_vel', kind, _NUMBERS.sub('#', text)), kind,
                                   f'{robot}/cmd_vel {text}')

    def _on_trajectory(self, robot: str, controller: str, msg: JointTrajectory) -> None:
        self._stepping.command_arrived()
        result = self._runner.set_trajectory(robot, controller,
                                             messages.trajectory_request(msg))
        where = f'{robot}/{controller}'
        if result.accepted:
            self._actions.preempt((robot, controller), 'preempted by a trajectory on the topic')
            self.get_logger().info(f'{where}: following a trajectory of {len(msg.points)} '
                                   f'points for {list(msg.joint_names)}')
            return
        self._diagnostics.trajectory_refused(
            robot, controller, 'rejected', result.reason,
            (robot, controller, _NUMBERS.sub('#', result.reason)),
            f'{where}: trajectory rejected: {result.reason}; holding position')

    def _on_suction(self, robot: str, request, response):
        suction = self._world.suctions[robot]
        source = self._world.source
        response.success, response.message = (suction.switch_on(source) if request.data
                                               else suction.release(source))
        service = self._world.robots[robot].config.suction
        text = (f'{robot}/{service.service if service else "suction"} '
                f'{"on" if request.data else "off"}: {response.message}')
        # (rclpy forbids two severities from one logging call site.)
        if response.success:
            self.get_logger().info(text)
        else:
            self.get_logger().warn(text)
        return response

    def _on_set_parameters(self, params):
        for param in params:
            if param.name == 'belt_speed':
                why = self._set_belt_speed(float(param.value))
                if why:
                    return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)

    def _set_belt_speed(self, speed: float) -> str:
        """Why the belt cannot run at ``speed`` [m/s] (-1: the world file's), or '' once set."""
        conveyor = self._world.conveyor
        if conveyor is None:
            return 'this world has no conveyor'
        if speed == -1.0:
            speed = conveyor.config.belt_speed
        elif not speed >= 0.0:
            # (The belt runs one way: a negative speed would have been "set" and ignored.)
            return (f'belt_speed {speed} m/s: the belt runs forward only (>= 0, or -1 for the '
                    "world file's)")
        conveyor.speed = speed
        self.get_logger().info(f'belt speed {speed:.3f} m/s')
        return ''

    def _on_reset(self, _request, response):
        response.success, response.message = True, self._reset_world()
        return response

    def _reset_world(self) -> str:
        """Robots back at their start poses, the materials' scenario again, faults cleared
        (simulated time runs on); what was done. Step requests being served end first."""
        ended = self._stepping.end_steps('a reset')
        aborted = self._actions.abort_all(
            'the simulation was reset: the arm is back at its start pose', hold=False)
        faults = list(self._runner.faults)
        self._runner.reset()
        self._diagnostics.clear_brakes()
        self._outputs.hold_watch = HoldWatch(self._world)     # (simulated time starts again)
        now = self._world.sim_time_ns
        for name in self._world.robots:
            if name in self._runner.guards:
                self._outputs.publish_applied(name, now, ZERO)
            self._outputs.on_state(name, now)
        self.get_logger().info('world reset' + (f'; goals aborted: {", ".join(aborted)}'
                                                if aborted else ''))
        return 'robots returned to their start poses' + (
            f' (faults cleared: {", ".join(faults)})' if faults else '') + (
            f' (goals aborted: {", ".join(aborted)})' if aborted else '') + (
            f'; {ended}' if ended else '')

    def _quit_soon(self) -> None:
        """End the run a second after the reply that asked for it (the reply must reach its
        client before the node is gone: on a loaded machine it was lost)."""
        def quit_now() -> None:
            timer.cancel()
            self.exit_request.set()
        timer = self.create_timer(QUIT_DELAY_S, quit_now,
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))

    def destroy_node(self) -> None:
        # Leave no robot driving on a stale command.
        self._runner.stop_all()
        self._entities.spawner.close()
        self._world.close()
        super().destroy_node()


def main(args=None) -> int:
    return run_node(SimNode, 'sim_node',
                    (SimConfigError, WorldConfigError, WorldError, FileNotFoundError), args=args)


if __name__ == '__main__':
    sys.exit(main())
