"""The pipeline coordinator node: wires the state machines (coordinator.pipeline) to the node
graph through its observer (observer.py: what it sees, the run's clock, lock-step) and its
ports (ros_ports.py: what it does), and reports the scored result.

Inputs (each robot in its namespace, as the world names it; the paper's ``/zu12`` and
``/youbot``): ``/detections`` (vision_node), each arm's ``joint_states``, each youBot's
``odom``, the grip states of the loader's cup and the youBot's gripper; for the score only,
the simulator's ground truth ``/cell/materials``. Outputs: arm trajectories, the grip
services, each youBot's ``cmd_vel``, the belt speed (the simulator's ``belt_speed``
parameter), IK through each arm's ``solve_ik``; ``~/events`` and ``~/state`` (latched).

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
import json
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from sim_interfaces.msg import PipelineState

from cell_layout.joint_speeds import speed_limits
from cell_layout.layout import CellLayout, LayoutError
from cell_layout.link_clearance import link_clearance
from cell_layout.scan_map import localizers
from cell_layout.world_layout import layout_from_world, with_extra_materials
from controllers.lockstep import CommandCounter
from coordinator.observer import Observer
from coordinator.pipeline import (
    Event,
    EventKind,
    NodeTimeout,
    Pipeline,
    Settings,
    known,
)
from coordinator.ros_ports import RosPorts, Stopped
from ros_common.node_main import run_task
from ros_common.outputs import write_file
from ros_common.params import Param, declare_params
from ros_common.stamps import stamp_from_ns
from trial_record.result import TrialResult, code_version
from trial_record.scoring import (
    RunTrace,
    build_result,
    destinations,
)
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfig, load_world

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
    Param('pick_x', -0.6, 'The loader picks materials on the belt downstream of this x, or of '
          'where its arm reaches the belt from if that is further [m]',
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
    Param('odometry_drift', 0.05, "How far a youBot's odometry may drift, per metre driven and "
          'per radian turned, as its laser localization assumes (a youBot with a laser '
          'scanner)', 0.001, 0.5),
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
    link_clearance(layout)      # (its collision model built now, not on the first swing)
    return layout


def transport_states(transports: Sequence[Any]) -> str:
    """The published ``transport_state``: the youBot's state; a fleet's, each youBot's by
    its name, in the cell's order ('youbot: drive, youbot2: wait_bay')."""
    if len(transports) == 1:
        return str(transports[0].state.value)
    return ', '.join(f'{t.robot}: {t.state.value}' for t in transports)


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
        dt_ns = round(float(p['time_step']) * 1e9)
        steps_per_tick = max(1, round(1e9 / self.rate / dt_ns))
        state_period = round(1e9 / float(p['state_publish_rate']))
        if self.synchronous and state_period > steps_per_tick * dt_ns:
            raise CoordinatorError('lock-step needs state_publish_rate >= control_rate')
        cams = [c for c in self.world.cameras if c.name == 'belt_camera']
        encoder = self.world.conveyor.encoder if self.world.conveyor is not None else None
        self.service_timeout = float(p['service_timeout'])
        self.result_file = p['result_file']
        self.progress_file = Path(p['progress_file']) if p['progress_file'] else None
        self.seed = int(p['scenario_seed'])
        self.regions = destinations(layout)
        self._started = time.monotonic()
        # Each youBot's path, as its odometry saw it at every decision (the first's is the
        # result's youbot_path).
        self._paths: Dict[str, List[Tuple[float, float]]] = {
            r.name: [] for r in layout.transports}
        # Lock-step: the commands of each decision are announced with the next step request,
        # and stamped with the decision's own step time (the plan's), not with a /clock that
        # may lag it.
        commands = CommandCounter()
        sim = p['sim_node'].rstrip('/')
        arms = {name: robot.joints for name, robot in layout.robots.items()}
        self.observer = Observer(
            self, layout, arms, sim, self.synchronous, self.rate, dt_ns, state_period,
            round(1e9 / cams[0].rate) if cams else None,
            round(1e9 / encoder.rate) if encoder is not None else None, self.service_timeout,
            float(p['drive_lead']), commands,
            {arm: speed_limits(self.world, arm) for arm in arms},
            drive=lambda base, vx, vy, wz: self.ports.drive(base, vx, vy, wz),
            localizers={base: (loc, round(1e9 / rate))
                        for base, (loc, rate) in localizers(self.world, {
                            r.name: self.world.robot(r.name).pose.z
                            for r in layout.transports}, float(p['odometry_drift'])).items()})
        self.ports = RosPorts(self, layout, sim, self.settings, self.synchronous,
                              self.service_timeout, commands, now=self.observer.now,
                              set_follower=self.observer.inputs.set_follower,
                              on_event=self._on_event)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.state_pub = self.create_publisher(PipelineState, '~/state', latched)
        self.get_logger().info(
            f'{"lock-step" if self.synchronous else "real-time"} at {self.rate:g} Hz '
            f'({steps_per_tick} steps per decision); belt {layout.belt_speed:.3f} m/s, '
            f'{layout.total} materials {layout.manifest}; picks from x = '
            f'{max(self.settings.pick_x, layout.pick_from):.3f} m')

    def now(self) -> float:
        return self.observer.now()

    def _on_event(self, e: Event) -> None:
        """What the node does on the pipeline's events beyond publishing them."""
        if e.kind is EventKind.SEEN:
            self.observer.inputs.check_identification(self.pipeline.materials.get(e.material))
        if e.kind is EventKind.LOADING_OVER:
            # No material will be seen again: no camera frame is waited for any more.
            self.observer.stop_frames()

    # --- the loop -----------------------------------------------------------------------------
    def run(self) -> TrialResult:
        try:
            obs = self.observer.first(
                [*self.ports.ik.values(), *self.ports.grips.values(), self.ports.param_client])
            belt_ran_before = self.observer.belt_runs_at_layout_speed()
        except (NodeTimeout, Stopped) as exc:
            self.pipeline = Pipeline(self.layout, self.ports, self.settings, self.now())
            self.pipeline.abort(self.now(), *(('interrupted', 'shut down before the start')
                                              if isinstance(exc, Stopped)
                                              else ('node_timeout', str(exc))))
            return self._report()
        self.pipeline = Pipeline(self.layout, self.ports, self.settings, obs.now, belt_ran_before)
        ticks = 0
        try:
            while not self.pipeline.finished and rclpy.ok():
                self.pipeline.tick(obs)
                for base, path in self._paths.items():
                    path.append(obs.bases[base].pose[:2])
                ticks += 1
                if ticks % max(1, round(self.rate)) == 0:
                    self._publish_state(obs.now)
                if self.pipeline.finished:
                    break
                obs = self.observer.next(obs)
        except NodeTimeout as exc:
            self.pipeline.abort(self.now(), 'node_timeout', str(exc))
        except Stopped:
            pass                  # (the simulator and the vision stop with it: nothing comes)
        if not self.pipeline.finished:
            self.pipeline.abort(self.now(), 'interrupted', 'shut down before the end')
        return self._report()

    # --- the end ------------------------------------------------------------------------------
    def _report(self) -> TrialResult:
        result = known(self.pipeline.result, 'the result')
        truth = self.observer.final_truth(self.pipeline.start_time + result.completion_time)
        seen = self.observer.inputs
        with seen.lock:
            identified = seen.identifications.finish()
            trace = RunTrace(
                seed=self.seed, belt_speed=self.layout.belt_speed,
                mode='lock-step' if self.synchronous else 'real-time',
                start=self.pipeline.start_time,
                identification_details=list(seen.identifications.details),
                peaks=dict(seen.peak),
                joint_names={arm: list(limits) for arm, limits in seen.speed_joints.items()},
                driven_past=list(seen.driven_past),
                youbot_path=list(self._paths[self.layout.transport.name]),
                events=list(self.pipeline.events),
                # How old the odometry was when the drive acted on it [s] (simulated time).
                odometry_age=None if self.synchronous else seen.drive_lead.summary(),
                closest_bases=seen.closest_bases if self.layout.fleet else None,
                paths=self._paths if self.layout.fleet else {})
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
                            transport_state=transport_states(p.transports),
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


def _run(node: CoordinatorNode) -> int:
    """0 for a completed run, 1 for any other; 0 too for a run stopped by Ctrl-C or SIGTERM
    (its result says 'interrupted'), as a ROS 2 node exits when it is stopped."""
    return 0 if node.run().status in ('completed', 'interrupted') else 1


def _stop_the_robots(node: CoordinatorNode) -> None:
    try:
        for base in node.layout.transports:
            node.ports.follow(base.name, None)
            node.ports.drive(base.name, 0.0, 0.0, 0.0)
    except Exception:
        pass


def main(args=None) -> int:
    return run_task(CoordinatorNode, 'coordinator_node', _run,
                    (CoordinatorError, FileNotFoundError, KeyError, ValueError),
                    on_exit=_stop_the_robots, background_spin=True, args=args)


if __name__ == '__main__':
    sys.exit(main())
