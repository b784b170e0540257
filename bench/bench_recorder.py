"""Benchmark of the recorder: throughput against a raw rosbags write, and CPU cost in a run.

1. Throughput. A publisher process sends N pre-serialized rgb8 images (640x480 and 320x240) as
   fast as it can; a recorder node in a worker process writes them to an MCAP bag. The
   baseline, in the same run and the same directory: rosbags' Writer writing N distinct frames
   of the same size from memory, with no ROS in between, in a worker process with the same
   allocator settings. Two configurations, each in fresh processes (Fast DDS reads its profile
   once per process):
   - "defaults": Fast DDS's default transports (a 512 KiB shared-memory segment) and glibc's
     default allocator thresholds;
   - "project": the project's Fast DDS profile (``ros_common/config/fastdds.xml``) and the
     allocator thresholds every node sets (``ros_common/memory.py``).
   Runs are interleaved and repeated; the tables give medians, with the range.
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
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Dict, List

HERE = Path(__file__).resolve().parent

PUBLISHER = '''
import sys, time, rclpy
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image
count, width, height = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
rclpy.init()
node = rclpy.create_node('bench_publisher')
pub = node.create_publisher(Image, '/bench/image', QoSProfile(depth=1000))
msg = Image(width=width, height=height, encoding='rgb8', step=3 * width,
            data=bytes(range(256)) * (3 * width * height // 256) + bytes(3 * width * height % 256))
raw = serialize_message(msg)
end = time.monotonic() + 30
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(1.0)
t0 = time.perf_counter()
for i in range(count):
    pub.publish(raw)
pub.wait_for_all_acked(rclpy.duration.Duration(seconds=30))
t1 = time.perf_counter()
print(count / (t1 - t0), flush=True)
'''

CONFIGS = tuple(os.environ.get('BENCH_CONFIGS', 'defaults project').split())
SIZES = ((640, 480),) if os.environ.get('BENCH_SMALL') else ((640, 480), (320, 240))


def _frame(width: int, height: int, fill: int = 0) -> bytes:
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image
    msg = Image(width=width, height=height, encoding='rgb8', step=3 * width,
                data=bytes([fill]) * (3 * width * height))
    return serialize_message(msg)


def worker_raw(count: int, width: int, height: int, out: Path) -> Dict:
    """rosbags' Writer alone: ``count`` distinct frames, already in memory."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from recording.types import TypeResolver
    frames = [_frame(width, height, i % 256) for i in range(count)]
    msgdef, rihs01 = TypeResolver().definition('sensor_msgs/msg/Image')
    writer = Writer(out / 'raw', version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection('/bench/image', 'sensor_msgs/msg/Image', msgdef=msgdef,
                                 rihs01=rihs01)
    t0, c0 = time.perf_counter(), time.process_time()
    for i, frame in enumerate(frames):
        writer.write(conn, i, frame)
    writer.close()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {'messages': count, 'mb_per_s': count * len(frames[0]) / wall / 1e6,
            'msgs_per_s': count / wall, 'cpu_ms_per_msg': 1e3 * cpu / count}


def worker_recorder(count: int, width: int, height: int, out: Path, drain: bool = False
                    ) -> Dict:
    """The recorder node, instrumented, fed by a publisher process. ``drain``: the recorder
    takes nothing until the publisher has sent everything (into the reader's history), so the
    figures are the recorder's own take-and-write, without the sending."""
    import rclpy
    from rclpy.parameter import Parameter

    from recording.recorder import Recorder
    from ros_common.node_main import make_executor
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Recorder(context=ctx, parameter_overrides=[
        Parameter('output_dir', value=str(out)), Parameter('bag_name', value='rec'),
        Parameter('topics', value=['/bench/image'])])
    marks: List = []        # (wall, process CPU, bytes) after each write
    original = node._writer.write

    def instrumented(topic, stamp, data):
        original(topic, stamp, data)
        marks.append((time.perf_counter(), time.process_time(), len(data)))

    node._writer.write = instrumented
    executor = make_executor(node)
    executor.add_node(node)
    stop, gate = threading.Event(), threading.Event()
    gate.set()

    def spin() -> None:
        while not stop.is_set():
            if gate.is_set():
                executor.spin_once(timeout_sec=0.05)
            else:
                time.sleep(0.01)
            if drain and '/bench/image' in node._writer.topics and not marks:
                gate.clear()        # subscribed: hold the takes until everything is sent

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    try:
        publisher = subprocess.run(
            [sys.executable, '-c', PUBLISHER, str(count), str(width), str(height)],
            check=True, timeout=300, capture_output=True, text=True)
        drain = False
        gate.set()
        end = time.monotonic() + 60.0
        while len(marks) < count and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.5)
    finally:
        stop.set()
        spinner.join(5)
        node.finish()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    sent = float(publisher.stdout.strip().splitlines()[-1])    # messages/s, until all acked
    return _recorder_figures(count, marks, sent)


def _recorder_figures(count: int, marks: List, sent: float) -> Dict:
    """Rates from the marks after each write (wall, CPU, bytes) and the publisher's rate."""
    if len(marks) < 2:
        return {'published': count, 'recorded': len(marks), 'mb_per_s': float('nan'),
                'msgs_per_s': float('nan'), 'cpu_ms_per_msg': float('nan'),
                'sent_mb_per_s': float('nan')}
    wall, cpu = marks[-1][0] - marks[0][0], marks[-1][1] - marks[0][1]
    return {'published': count, 'recorded': len(marks),
            'sent_mb_per_s': sent * marks[-1][2] / 1e6,
            'mb_per_s': sum(m[2] for m in marks[1:]) / wall / 1e6,
            'msgs_per_s': (len(marks) - 1) / wall,
            'cpu_ms_per_msg': 1e3 * cpu / (len(marks) - 1)}


def _worker_main(argv: List[str]) -> int:
    kind, config, count, width, height, out = argv
    if config == 'project':
        from ros_common.memory import keep_large_blocks
        keep_large_blocks()
    args = (int(count), int(width), int(height), Path(out))
    result = (worker_raw(*args) if kind == 'raw' else
              worker_recorder(*args, drain=kind == 'drain'))
    print(json.dumps(result), flush=True)
    return 0


def _environment(config: str) -> Dict[str, str]:
    from ros_common.dds import PROFILE_VARIABLES, with_profile
    base = {k: v for k, v in os.environ.items() if k not in PROFILE_VARIABLES}
    return with_profile(base) if config == 'project' else base


def _run_worker(kind: str, config: str, count: int, width: int, height: int,
                out: Path) -> Dict:
    out.mkdir(parents=True)
    try:
        done = subprocess.run([sys.executable, __file__, '--worker', kind, config, str(count),
                               str(width), str(height), str(out)], env=_environment(config),
                              check=True, timeout=600, capture_output=True, text=True)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


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


def _median(runs: List[Dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def _span(runs: List[Dict], key: str, fmt: str = '.0f') -> str:
    values = [r[key] for r in runs]
    return f'{statistics.median(values):{fmt}} ({min(values):{fmt}}-{max(values):{fmt}})'


def _table(runs: Dict[str, List[Dict]], count: int) -> Dict[str, Dict]:
    """Print the table of the runs' medians; the summary per payload and configuration."""
    print('\n| payload | configuration | raw rosbags write | recorder | sent | recorder / raw | '
          'drain | drain / raw | recorder CPU ms per frame: streaming, drain (raw write) | '
          'recorded |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    summary = {}
    for width, height in SIZES:
        for config in CONFIGS:
            key = f'{width}x{height} {config}'
            raw, rec, drain = (runs[f'{kind} {key}'] for kind in ('raw', 'recorder', 'drain'))
            raw_mb = _median(raw, 'mb_per_s')
            summary[key] = {'raw_mb_per_s': raw_mb, 'recorder_mb_per_s': _median(rec, 'mb_per_s'),
                            'sent_mb_per_s': _median(rec, 'sent_mb_per_s'),
                            'drain_mb_per_s': _median(drain, 'mb_per_s'),
                            'ratio': _median(rec, 'mb_per_s') / raw_mb,
                            'drain_ratio': _median(drain, 'mb_per_s') / raw_mb}
            recorded = ', '.join(f'{min(r["recorded"] for r in x)}-{max(r["recorded"] for r in x)}'
                                 for x in (rec, drain))
            print(f'| rgb8 {width}x{height} | {config} | {_span(raw, "mb_per_s")} | '
                  f'{_span(rec, "mb_per_s")} | {_span(rec, "sent_mb_per_s")} | '
                  f'{summary[key]["ratio"]:.2f} | {_span(drain, "mb_per_s")} | '
                  f'{summary[key]["drain_ratio"]:.2f} | {_median(rec, "cpu_ms_per_msg"):.2f}, '
                  f'{_median(drain, "cpu_ms_per_msg"):.2f} ({_median(raw, "cpu_ms_per_msg"):.2f})'
                  f' | {recorded} of {count} |')
    return summary


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == '--worker':
        return _worker_main(sys.argv[2:])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--count', type=int, default=600)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--cpu-seconds', type=float, default=15.0)
    parser.add_argument('--dir', type=Path, default=None,
                        help='where the bags are written (default: the system temp directory)')
    args = parser.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(101, 159)))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    work = Path(tempfile.mkdtemp(prefix='bench_recorder_', dir=args.dir))
    runs: Dict[str, List[Dict]] = {}
    try:
        n = 0
        for repeat in range(args.repeats):
            for width, height in SIZES:
                for config in CONFIGS:
                    key = f'{width}x{height} {config}'
                    print(f'[{repeat + 1}/{args.repeats}] {args.count} rgb8 images {key} ...',
                          flush=True)
                    for kind in ('raw', 'recorder', 'drain'):
                        n += 1
                        runs.setdefault(f'{kind} {key}', []).append(_run_worker(
                            kind, config, args.count, width, height, work / str(n)))
        print(f'CPU cost of recording a real-time run ({args.cpu_seconds:g} s) ...', flush=True)
        cpu = recording_cpu(args.cpu_seconds, work / 'cpu')
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f'\nmedians of {args.repeats} interleaved runs (range); bags in {args.dir or "the "}'
          f'{"" if args.dir else "system temp directory"}')
    print('\nMB/s; "sent": how fast the publisher got its frames acknowledged; "drain": the '
          'recorder taking and writing frames already delivered, without the sending')
    summary = _table(runs, args.count)
    if {'defaults', 'project'} <= set(CONFIGS):
        gain = (summary['640x480 project']['recorder_mb_per_s']
                / summary['640x480 defaults']['recorder_mb_per_s'])
        print(f'\n640x480: the project\'s settings record {gain:.2f}x as fast as the defaults')
    best = summary[f'640x480 {CONFIGS[-1]}']
    print(f'640x480, {CONFIGS[-1]}: recorder / raw write {best["ratio"]:.2f} while streaming (the '
          f'publisher sent {best["sent_mb_per_s"]:.0f} MB/s), {best["drain_ratio"]:.2f} for the '
          'recorder\'s own take-and-write (goal 0.8)')
    print(f'\nrecording a real-time mini-robot run with its camera: recorder '
          f'{cpu["recorder_cpu_percent"]:.1f} % of a core, sim_node '
          f'{cpu["sim_cpu_percent"]:.1f} %\n{cpu["summary"]}')
    out_dir = HERE / 'results'
    out_dir.mkdir(exist_ok=True)
    (out_dir / 'bench_recorder.json').write_text(json.dumps(
        {'runs': runs, 'summary': summary, 'cpu': cpu}, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
