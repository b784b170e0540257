"""Benchmark of the recorder: throughput against a raw rosbags write, and CPU cost in a run.

1. Throughput: a publisher process sends N pre-serialized messages as fast as it can; the
   recorder node runs in this process, instrumented, and writes them to an MCAP bag. Baseline
   in the same run: rosbags' Writer writing the same bytes with no ROS in between.
2. CPU cost: sim_node at real time with its camera (320x240 @ 15 Hz) and the recorder process
   on all topics for a while; the recorder's CPU time from /proc against wall time.

Prints the figures; writes JSON to bench/results/.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from sensor_msgs.msg import Image

from recording.recorder import Recorder
from recording.types import TypeResolver

HERE = Path(__file__).resolve().parent

PUBLISHER = '''
import sys, time, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image
count, width, height = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
rclpy.init()
node = rclpy.create_node('bench_publisher')
pub = node.create_publisher(Image, '/bench/image', QoSProfile(depth=1000))
msg = Image(width=width, height=height, encoding='rgb8', step=3 * width,
            data=bytes(range(256)) * (3 * width * height // 256) + bytes(3 * width * height % 256))
end = time.monotonic() + 30
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(1.0)
for i in range(count):
    msg.header.stamp.sec = i
    pub.publish(msg)
pub.wait_for_all_acked(rclpy.duration.Duration(seconds=10))
print('done', flush=True)
'''


def _image_bytes(width: int, height: int) -> bytes:
    msg = Image(width=width, height=height, encoding='rgb8', step=3 * width,
                data=bytes(3 * width * height))
    return serialize_message(msg)


def raw_write(count: int, payload: bytes, out: Path) -> dict:
    typestore_resolver = TypeResolver()
    msgdef, rihs01 = typestore_resolver.definition('sensor_msgs/msg/Image')
    writer = Writer(out / 'raw', version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection('/bench/image', 'sensor_msgs/msg/Image', msgdef=msgdef,
                                 rihs01=rihs01)
    t0 = time.perf_counter()
    for i in range(count):
        writer.write(conn, i, payload)
    writer.close()
    wall = time.perf_counter() - t0
    return {'messages': count, 'mb_per_s': count * len(payload) / wall / 1e6,
            'msgs_per_s': count / wall}


def recorder_throughput(count: int, width: int, height: int, out: Path) -> dict:
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Recorder(context=ctx, parameter_overrides=[
        Parameter('output_dir', value=str(out)), Parameter('bag_name', value='rec'),
        Parameter('topics', value=['/bench/image'])])
    times, sizes = [], []
    original = node._writer.write

    def instrumented(topic, stamp, data):
        original(topic, stamp, data)
        times.append(time.perf_counter())
        sizes.append(len(data))

    node._writer.write = instrumented
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [executor.spin_once(timeout_sec=0.05)
                                               for _ in iter(stop.is_set, True)], daemon=True)
    spinner.start()
    try:
        subprocess.run([sys.executable, '-c', PUBLISHER, str(count), str(width), str(height)],
                       check=True, timeout=300, capture_output=True)
        time.sleep(1.0)
    finally:
        stop.set()
        spinner.join(5)
        node.finish()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    wall = times[-1] - times[0] if len(times) > 1 else float('nan')
    return {'published': count, 'recorded': len(times),
            'mb_per_s': sum(sizes[1:]) / wall / 1e6, 'msgs_per_s': (len(times) - 1) / wall}


def _cpu_seconds(pid: int) -> float:
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def recording_cpu(seconds: float, out: Path) -> dict:
    sim = subprocess.Popen(['sim_node', '--ros-args', '-p', 'rtf_log_period:=0.0'],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rec = subprocess.Popen(['recorder', '--ros-args', '-p', f'output_dir:={out}', '-p',
                            'bag_name:=run'], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True)
    try:
        time.sleep(5.0)  # start-up and discovery
        c0, s0, t0 = _cpu_seconds(rec.pid), _cpu_seconds(sim.pid), time.monotonic()
        time.sleep(seconds)
        c1, s1, t1 = _cpu_seconds(rec.pid), _cpu_seconds(sim.pid), time.monotonic()
    finally:
        rec.send_signal(2)
        summary = rec.communicate(timeout=30)[0]
        sim.send_signal(2)
        sim.wait(30)
    line = next((ln for ln in summary.splitlines() if 'closed with' in ln), '')
    return {'recorder_cpu_percent': 100 * (c1 - c0) / (t1 - t0),
            'sim_cpu_percent': 100 * (s1 - s0) / (t1 - t0), 'summary': line}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--count', type=int, default=600)
    parser.add_argument('--cpu-seconds', type=float, default=15.0)
    args = parser.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(101, 200)))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    work = Path(tempfile.mkdtemp(prefix='bench_recorder_'))
    results = {}
    try:
        for width, height in ((320, 240), (640, 480)):
            key = f'{width}x{height}'
            print(f'throughput, {args.count} rgb8 images {key} ...', flush=True)
            results[f'raw_{key}'] = raw_write(args.count, _image_bytes(width, height),
                                              work / f'raw_{key}')
            results[f'recorder_{key}'] = recorder_throughput(args.count, width, height,
                                                             work / f'rec_{key}')
        print(f'CPU cost of recording a real-time run ({args.cpu_seconds:g} s) ...', flush=True)
        results['cpu'] = recording_cpu(args.cpu_seconds, work / 'cpu')
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print('\n| payload | raw rosbags write MB/s (msg/s) | recorder MB/s (msg/s) | recorded |')
    print('|---|---|---|---|')
    for key in ('320x240', '640x480'):
        raw, rec = results[f'raw_{key}'], results[f'recorder_{key}']
        print(f'| rgb8 {key} | {raw["mb_per_s"]:.0f} ({raw["msgs_per_s"]:.0f}) | '
              f'{rec["mb_per_s"]:.1f} ({rec["msgs_per_s"]:.0f}) | '
              f'{rec["recorded"]}/{rec["published"]} |')
    cpu = results['cpu']
    print(f'\nrecording a real-time mini-robot run with its camera: recorder '
          f'{cpu["recorder_cpu_percent"]:.1f} % of a core, sim_node '
          f'{cpu["sim_cpu_percent"]:.1f} %\n{cpu["summary"]}')
    out_dir = HERE / 'results'
    out_dir.mkdir(exist_ok=True)
    (out_dir / 'bench_recorder.json').write_text(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
