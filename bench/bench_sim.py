"""Benchmark of the simulator node against raw PyBullet stepping of the same world.

1. Raw baseline (no ROS): the default world stepped in a loop, with the 320x240 camera rendered
   at 15 Hz of simulated time, as the node does when someone subscribes.
2. The node: sim_node as a separate process, as fast as possible (real_time_factor 0), with a
   subscriber on the camera so it renders; real-time factor from /clock against wall time.
3. Latency from cmd_vel publication (another process) to the wheel command being applied
   (the PyBullet motor call), with the node run in this process and instrumented.

Prints the figures and the node/raw ratio; writes JSON to bench/results/.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from sim_bridge.runner import DriveLimits, NullSink, SimRunner  # noqa: E402
from sim_bridge.world import SimWorld  # noqa: E402
from world_description.resources import resolve_resource  # noqa: E402
from world_description.world_config import load_world  # noqa: E402

WORLD = 'package://world_description/worlds/mini_robot.yaml'


class _CameraSink(NullSink):
    """A StepSink that wants every camera frame and discards it (the raw baseline)."""

    def __init__(self, camera: bool) -> None:
        self.camera, self.frames = camera, 0

    def on_camera_due(self, i, t, render):
        if self.camera:
            render()
            self.frames += 1


def raw_pybullet(seconds: float, camera: bool) -> dict:
    world = SimWorld(load_world(resolve_resource(WORLD)))
    runner = SimRunner(world, DriveLimits(), 100.0)
    sink = _CameraSink(camera)
    runner.command('mini_robot', 0.1, 0.0, 0.1)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        if steps % 24 == 0:
            runner.command('mini_robot', 0.1, 0.0, 0.1)
        runner.advance(1, sink)
        steps += 1
    wall = time.perf_counter() - t0
    world.close()
    return {'steps_per_s': steps / wall, 'rtf': steps * world.time_step / wall,
            'frames_per_wall_s': sink.frames / wall}


def node_rtf(seconds: float, camera: bool) -> dict:
    env = dict(os.environ)
    proc = subprocess.Popen(['sim_node', '--ros-args', '-p', 'real_time_factor:=0.0', '-p',
                             'rtf_log_period:=0.0'], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node('bench_probe', context=ctx)
    clocks, frames = [], [0]
    node.create_subscription(Clock, '/clock', lambda m: clocks.append(
        (time.perf_counter(), m.clock.sec + m.clock.nanosec * 1e-9)), 10)
    if camera:
        node.create_subscription(Image, '/mini_robot/camera/image_raw',
                                 lambda m: frames.__setitem__(0, frames[0] + 1),
                                 qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        end = time.perf_counter() + 30.0
        while not clocks and time.perf_counter() < end:
            executor.spin_once(timeout_sec=0.1)
        # Let discovery of the image subscription settle before measuring.
        warm = time.perf_counter() + 2.0
        while time.perf_counter() < warm:
            executor.spin_once(timeout_sec=0.05)
        start, f0 = clocks[-1], frames[0]
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            executor.spin_once(timeout_sec=0.05)
        last = clocks[-1]
        wall = last[0] - start[0]
        return {'rtf': (last[1] - start[1]) / wall, 'steps_per_s': (last[1] - start[1])
                / (1 / 240) / wall, 'frames_per_wall_s': (frames[0] - f0) / wall}
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        proc.terminate()
        proc.wait(10)


def latency(count: int, real_time_factor: float) -> dict:
    from sim_bridge.sim_node import SimNode
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = SimNode(context=ctx, parameter_overrides=[
        Parameter('real_time_factor', value=real_time_factor),
        Parameter('rtf_log_period', value=0.0)])
    robot = node._world.robots['mini_robot']
    applied = {}
    original = robot.set_body_twist

    def instrumented(v, vy, w):
        applied.setdefault(round(v, 7), time.monotonic())  # CLOCK_MONOTONIC: system-wide
        return original(v, vy, w)

    robot.set_body_twist = instrumented
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [executor.spin_once(timeout_sec=0.05)
                                               for _ in iter(stop.is_set, True)], daemon=True)
    spinner.start()
    try:
        out = subprocess.run([sys.executable, str(HERE / 'latency_publisher.py'), str(count)],
                             capture_output=True, text=True, timeout=120, check=True)
        published = json.loads(out.stdout)
        time.sleep(0.5)
    finally:
        stop.set()
        spinner.join(5)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    lat = [1e3 * (applied[round(v, 7)] - t) for v, t in published if round(v, 7) in applied]
    return {'messages': len(published), 'applied': len(lat),
            'median_ms': statistics.median(lat), 'p99_ms': float(np.percentile(lat, 99)),
            'max_ms': max(lat)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0, help='per RTF measurement')
    parser.add_argument('--latency-count', type=int, default=1000)
    args = parser.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(101, 200)))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    results = {}
    print(f'raw PyBullet, default world, camera 320x240 at 15 Hz ({args.seconds:g} s) ...',
          flush=True)
    results['raw_camera'] = raw_pybullet(args.seconds, camera=True)
    results['raw_physics_only'] = raw_pybullet(args.seconds / 2, camera=False)
    print('sim_node, as fast as possible, camera subscribed ...', flush=True)
    results['node_camera'] = node_rtf(args.seconds, camera=True)
    results['node_no_subscriber'] = node_rtf(args.seconds / 2, camera=False)
    print('cmd_vel -> wheel command latency ...', flush=True)
    results['latency_rtf1'] = latency(args.latency_count, 1.0)
    results['latency_afap'] = latency(args.latency_count, 0.0)

    rc, rn = results['raw_camera'], results['node_camera']
    print()
    print('| measurement | real-time factor | steps/s | camera frames per wall s |')
    print('|---|---|---|---|')
    for key, label in (('raw_physics_only', 'raw PyBullet, physics only'),
                       ('raw_camera', 'raw PyBullet + camera 320x240 @ 15 Hz'),
                       ('node_camera', 'sim_node AFAP, camera subscribed'),
                       ('node_no_subscriber', 'sim_node AFAP, no camera subscriber')):
        r = results[key]
        print(f'| {label} | {r["rtf"]:.2f} | {r["steps_per_s"]:.0f} | '
              f'{r["frames_per_wall_s"]:.1f} |')
    print(f'\nnode / raw (camera on): {rn["rtf"] / rc["rtf"]:.2f}')
    for key, label in (('latency_rtf1', 'real-time pacing'),
                       ('latency_afap', 'as fast as possible')):
        r = results[key]
        print(f'cmd_vel -> wheel command ({label}): median {r["median_ms"]:.2f} ms, '
              f'p99 {r["p99_ms"]:.2f} ms, max {r["max_ms"]:.2f} ms '
              f'({r["applied"]}/{r["messages"]} messages)')
    out_dir = HERE / 'results'
    out_dir.mkdir(exist_ok=True)
    (out_dir / 'bench_sim.json').write_text(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
