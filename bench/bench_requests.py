"""Benchmark of what a careless or hostile client costs the simulator (issue 47).

1. Over DDS, sim_node (the pipeline cell, lock-step) as a separate process: the reply time of
   each request of the issue (a backtracking name filter, 315 kB of "<robot ", 5,000 spawns in
   one call, a velocity of 1e300 m/s, a stop of a 10,000,000-step request), and the reply time
   of get_simulation_state sent by another client while each is served: the node's
   responsiveness against its own quiet baseline, taken in the same run.
2. Without ROS: the pipeline cell's physics step with the free bodies' watch (free_bodies.py:
   every material's velocity after each step) against the same world stepped by PyBullet alone,
   and with 200 spawned boxes; the ratio is the watch's cost.

Prints the figures and writes JSON to bench/results/.
"""
from __future__ import annotations

import json
import os
import random
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, List

HERE = Path(__file__).resolve().parent

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from simulation_interfaces.msg import EntityFilters, SimulationState  # noqa: E402
from simulation_interfaces.msg import SpawnEntity as SpawnRequest  # noqa: E402
from simulation_interfaces.srv import (  # noqa: E402
    GetEntities,
    GetSimulationState,
    SetEntityState,
    SetSimulationState,
    SpawnEntities,
    SpawnEntity,
    StepSimulation,
)

from ros_common.services import SERVICE_QOS  # noqa: E402

PIPELINE = 'package://world_description/worlds/pipeline_cell.yaml'
SIM = '/sim_node'


class Client:
    """A node of its own per client, spun in a thread: the hostile one and a bystander."""

    def __init__(self, name: str) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: Dict[str, Any] = {}
        self._run = True
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while self._run:
            self.executor.spin_once(timeout_sec=0.02)

    def prepare(self, srv: Any, name: str) -> None:
        """The client of a service, its server discovered (before anything is timed)."""
        self.call_async(srv, name, None)

    def call_async(self, srv: Any, name: str, request: Any) -> Any:
        client = self._clients.get(name)
        if client is None:
            client = self._clients[name] = self.node.create_client(srv, f'{SIM}/{name}',
                                                                   qos_profile=SERVICE_QOS)
            if not client.wait_for_service(timeout_sec=60.0):
                raise RuntimeError(f'{name} not available')
        return client.call_async(request) if request is not None else None

    def call(self, srv: Any, name: str, request: Any, timeout: float = 600.0) -> Any:
        future = self.call_async(srv, name, request)
        end = time.monotonic() + timeout
        while not future.done():
            if time.monotonic() > end:
                raise TimeoutError(name)
            time.sleep(0.0005)
        return future.result()

    def close(self) -> None:
        self._run = False
        self._thread.join(2.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _bystander(client: Client, busy: threading.Event, out: List[float]) -> None:
    """get_simulation_state, one after another, while ``busy`` is set: their reply times."""
    while busy.is_set():
        t0 = time.perf_counter()
        client.call(GetSimulationState, 'get_simulation_state', GetSimulationState.Request())
        out.append(time.perf_counter() - t0)


def _timed(hostile: Client, bystander: Client, request: Callable[[], Any]) -> Dict[str, float]:
    busy, replies = threading.Event(), []
    busy.set()
    thread = threading.Thread(target=_bystander, args=(bystander, busy, replies))
    thread.start()
    t0 = time.perf_counter()
    try:
        request()
    finally:
        took = time.perf_counter() - t0
        busy.clear()
        thread.join(60.0)
    return {'reply_ms': 1e3 * took, 'others_answered': len(replies),
            'others_max_ms': 1e3 * max(replies, default=0.0)}


def over_dds() -> Dict[str, Any]:
    proc = subprocess.Popen(['sim_node', '--ros-args', '-p', f'world:={PIPELINE}', '-p',
                             'synchronous:=true', '-p', 'step_chunk:=24'],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    hostile, bystander = Client('bench_hostile'), Client('bench_bystander')
    try:
        for srv, name in ((GetEntities, 'get_entities'), (SpawnEntity, 'spawn_entity'),
                          (SpawnEntities, 'spawn_entities'), (SetEntityState, 'set_entity_state'),
                          (StepSimulation, 'step_simulation'),
                          (SetSimulationState, 'set_simulation_state')):
            hostile.prepare(srv, name)
        quiet = []
        bystander.call(GetSimulationState, 'get_simulation_state', GetSimulationState.Request())
        for _ in range(200):
            t0 = time.perf_counter()
            bystander.call(GetSimulationState, 'get_simulation_state',
                           GetSimulationState.Request())
            quiet.append(time.perf_counter() - t0)
        base = {'median_ms': 1e3 * statistics.median(quiet), 'max_ms': 1e3 * max(quiet)}
        figures: Dict[str, Any] = {'quiet get_simulation_state': base}
        filters = EntityFilters(filter=r'(\w*\w*\w*\w*\w*\w*\w*\w*)*!')
        figures['backtracking filter'] = _timed(hostile, bystander, lambda: hostile.call(
            GetEntities, 'get_entities', GetEntities.Request(filters=filters)))
        urdf = SpawnEntity.Request(name='x', resource_string='<robot ' * 45_000)
        urdf.initial_pose.pose.orientation.w = 1.0
        figures['315 kB of <robot'] = _timed(hostile, bystander, lambda: hostile.call(
            SpawnEntity, 'spawn_entity', urdf))
        many = SpawnEntities.Request()
        for k in range(5000):
            box = SpawnRequest(name=f'b{k}')
            box.entity_resource.uri = 'shape://box?size=0.02,0.02,0.02'
            box.initial_pose.pose.position.z = 1.0
            box.initial_pose.pose.orientation.w = 1.0
            many.spawn_requests.append(box)
        figures['5,000 spawns'] = _timed(hostile, bystander, lambda: hostile.call(
            SpawnEntities, 'spawn_entities', many))
        state = SetEntityState.Request(entity='youbot')
        state.state.pose.position.x, state.state.pose.position.z = 0.8, 0.0815
        state.state.pose.orientation.w = 1.0
        state.state.twist.linear.x = 1e300
        figures['1e300 m/s'] = _timed(hostile, bystander, lambda: hostile.call(
            SetEntityState, 'set_entity_state', state))

        def long_step_stopped() -> None:
            future = hostile.call_async(StepSimulation, 'step_simulation',
                                        StepSimulation.Request(steps=10_000_000))
            time.sleep(1.0)
            hostile.call(SetSimulationState, 'set_simulation_state', SetSimulationState.Request(
                state=SimulationState(state=SimulationState.STATE_STOPPED)))
            while not future.done():
                time.sleep(0.001)
        figures['10,000,000 steps, stopped after 1 s'] = _timed(hostile, bystander,
                                                                long_step_stopped)
        return figures
    finally:
        hostile.close()
        bystander.close()
        proc.terminate()
        proc.wait(20)


def step_cost(seconds: float = 20.0, rounds: int = 10) -> Dict[str, Any]:
    """Steps per second of the pipeline cell: through SimWorld.step (the watch included) and
    PyBullet's own stepSimulation with the same belt and materials (the watch alone
    removed), then with 200 spawned boxes."""
    from sim_bridge.entities import Entities
    from sim_bridge.entity_types import State
    from sim_bridge.world import SimWorld
    from world_description.resources import resolve_resource
    from world_description.world_config import load_world
    out: Dict[str, Any] = {}
    for boxes in (0, 200):
        world = SimWorld(load_world(resolve_resource(PIPELINE)))
        entities = Entities(world, lambda w=world: w.sim_time)
        for k in range(boxes):
            entities.spawner.spawn(f'b{k}', False, 'shape://box?size=0.03,0.03,0.03&mass=0.1',
                                   '', '', State((-2.0 + (k % 20) * 0.06,
                                                  2.0 + (k // 20) * 0.06, 0.016),
                                                 (0.0, 0.0, 0.0, 1.0)))
        for _ in range(2400):                    # (the materials on the belt, the boxes at rest)
            world.step()
        # Rounds of each, interleaved (the machine's noise is slower than a round); medians.
        rates: Dict[str, List[float]] = {'watched': [], 'unwatched': []}
        check = world.check_free_bodies
        for _ in range(rounds):
            for name in rates:
                world.check_free_bodies = (check if name == 'watched'       # type: ignore
                                           else lambda pose=True: None)
                steps, t0 = 0, time.perf_counter()
                while time.perf_counter() - t0 < seconds / rounds:
                    world.step()
                    steps += 1
                rates[name].append(steps / (time.perf_counter() - t0))
        world.check_free_bodies = check                                     # type: ignore
        watched, unwatched = (statistics.median(rates[k]) for k in ('watched', 'unwatched'))
        out[f'{boxes} spawned boxes'] = {
            'materials': len(world.materials), 'steps_per_s_watched': watched,
            'steps_per_s_unwatched': unwatched, 'watch_cost_fraction': 1.0 - watched / unwatched}
        entities.spawner.close()
        world.close()
    return out


def main() -> int:
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(101, 159)))
    results = {'over_dds': over_dds(), 'step_cost': step_cost()}
    for name, figure in results['over_dds'].items():
        print(f'[requests] {name}: ' + ', '.join(f'{k} {v:.1f}' if isinstance(v, float) else
                                                 f'{k} {v}' for k, v in figure.items()))
    for name, figure in results['step_cost'].items():
        print(f'[requests] step, {name} ({figure["materials"]} materials): '
              f'{figure["steps_per_s_watched"]:.0f} steps/s watched, '
              f'{figure["steps_per_s_unwatched"]:.0f} unwatched: the watch costs '
              f'{100 * figure["watch_cost_fraction"]:.1f} %')
    out = HERE / 'results' / f'requests-{time.strftime("%Y%m%d-%H%M%S")}.json'
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=1))
    print(f'[requests] {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
