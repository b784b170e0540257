"""What the coordinator sees of the cell, over ROS: the arms' joint states and grips, the base's
odometry (in the cell's frame), the vision's detections, the simulator's ground truth (for the
score) and what it braked; and the run's clock. In lock-step it requests every step and, before
each decision, waits for the messages of exactly that step (states stamped with its time, the
detections of every camera frame it produced): the same seed gives the same run."""
from __future__ import annotations

import functools
import time
from typing import Any, Callable, Dict, Mapping, Optional, Sequence, Tuple

import rclpy
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from sim_interfaces.srv import StepSimulation

from cell_layout.layout import CellLayout
from controllers.lockstep import CommandCounter, DueGrid
from controllers.scan_localizer import ScanLocalizer
from coordinator.inputs import Inputs
from coordinator.pipeline import (
    ArmReading,
    BaseReading,
    NodeTimeout,
    Observation,
)
from coordinator.ros_ports import Stopped, call_service

CAMERA_TOPIC = '/belt_camera/image_raw'
STARTUP_GRACE_S = 1.0      # simulated seconds in which a lost camera frame is tolerated
STOP_CHECK_S = 0.2         # wall seconds between looks at a stop while waiting


class Observer:
    """The run's clock and its observations: in lock-step it requests every step and waits for
    exactly its messages; in real time it follows the simulator's clock. ``inputs``: what it
    has heard (``Inputs``)."""

    def __init__(self, node: Node, layout: CellLayout, arms: Mapping[str, Sequence[str]],
                 sim: str, synchronous: bool, rate: float, dt_ns: int, state_period_ns: int,
                 camera_period_ns: Optional[int], encoder_period_ns: Optional[int],
                 service_timeout: float, drive_lead: float,
                 commands: CommandCounter, speed_joints: Dict[str, Dict[str, float]],
                 drive: Callable[[str, float, float, float], None],
                 localizers: Mapping[str, Tuple[ScanLocalizer, int]]) -> None:
        """``localizers``: each base with a laser scanner, its localizer and its scans' period
        [ns]."""
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
        self.scan_grids = {base: DueGrid(dt_ns, period)
                           for base, (_, period) in localizers.items()}
        self._start_time = 0.0
        self.inputs = Inputs(node, layout, arms, sim, synchronous, drive_lead, speed_joints,
                             self.now, drive, {b: loc for b, (loc, _) in localizers.items()})
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
            for grid in (self.camera_grid, self.encoder_grid, *self.scan_grids.values()):
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
            self._wait_reading('belt encoder', lambda: self.inputs.belt_stamp, belt_due[-1])
        for base, grid in self.scan_grids.items():
            due = grid.advance(before, after)
            if due:
                self._wait_reading(f'{base} laser scan',
                                   functools.partial(self.inputs.scan_stamp.__getitem__, base),
                                   due[-1])
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
            if first and (self.encoder_grid and heard.belt_stamp < 0
                          or any(s < 0 for s in heard.scan_stamp.values())):
                return False            # (their first readings, at the first step)
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

    def _wait_reading(self, what: str, stamp: Callable[[], int], stamp_ns: int) -> None:
        """Until the reading (the encoder's, a scan) stamped ``stamp_ns`` is in."""
        with self.inputs.lock:
            if not self._wait(lambda: stamp() == stamp_ns, self.service_timeout):
                raise NodeTimeout(f'no {what} from the simulator for t = '
                                  f'{stamp_ns * 1e-9:.3f} s (latest: {stamp() * 1e-9:.3f} s)')

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
            bases = {name: BaseReading(*self.inputs.located(name, odom[1], odom[2]))
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

