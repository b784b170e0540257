"""Benchmark of the live view's gate: what relaying every client through it costs, against the
Foxglove SDK's server reached directly (the baseline, in the same run).

The server side (the SDK's server, and the gate in front of it for the gated runs) runs in this
process and logs camera-sized frames on one channel at a fixed rate; a client process
subscribes and reads everything. Each frame carries its send time (CLOCK_MONOTONIC, shared by
the two processes), so the client measures the latency of every frame it gets. Per
configuration and frame rate: frames delivered, median and 99th-percentile latency, and the
server side's CPU time per delivered MB. Configurations are interleaved and repeated; medians
are printed, with the ratio gate/direct.

Prints the figures; writes JSON to bench/results/.
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List

import foxglove

from live_view.bridge import SlowClients
from live_view.gate import Gate, self_signed_certificate
from ros_common.web_access import WebAccess

HERE = Path(__file__).resolve().parent
TOPIC = '/camera/image_raw'

CLIENT = r'''
import asyncio, json, struct, sys, time
import websockets

async def main(url, frames, timeout):
    got = []
    async with websockets.connect(url, subprotocols=['foxglove.sdk.v1'], max_size=None,
                                  compression=None) as ws:
        subscribed = False
        end = time.monotonic() + timeout
        while len(got) < frames and time.monotonic() < end:
            try:
                frame = await asyncio.wait_for(ws.recv(), 1.0)
            except asyncio.TimeoutError:
                if got:
                    break           # (the sender is done; what did not come is lost)
                continue
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg['op'] == 'advertise' and not subscribed:
                    channel = msg['channels'][0]['id']
                    await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                        {'id': 1, 'channelId': channel}]}))
                    subscribed = True
                    print('subscribed', flush=True)
                continue
            if frame[0] == 1:
                sent = struct.unpack_from('<q', frame, 13)[0]
                got.append(time.monotonic_ns() - sent)
    print(json.dumps(got), flush=True)

asyncio.run(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3])))
'''


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def run_once(gated: bool, rate: float, frames: int, size: int) -> Dict:
    certificate, key = self_signed_certificate()
    server = foxglove.start_server(host='127.0.0.1', port=0, supported_encodings=['cdr'],
                                   message_backlog_size=256,
                                   **({'tls_cert': certificate, 'tls_key': key} if gated
                                      else {}))
    gate = None
    url = f'ws://127.0.0.1:{server.port}'
    if gated:
        gate = Gate(WebAccess('127.0.0.1'), '127.0.0.1', 0, server.port, certificate, 4,
                    10_000_000, SlowClients(), lambda level, text, kind: None)
        url = f'ws://127.0.0.1:{gate.start()}'
    channel = foxglove.Channel(TOPIC, message_encoding='cdr', schema=foxglove.Schema(
        name='sensor_msgs/msg/Image', encoding='ros2msg', data=b'uint8[] data'))
    client = subprocess.Popen([sys.executable, '-c', CLIENT, url, str(frames), '60'],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout is not None
        assert client.stdout.readline().strip() == 'subscribed'
        time.sleep(0.5)                         # (the subscription reaches the server)
        payload = bytearray(size)
        cpu0, start = _cpu(), time.monotonic()
        for k in range(frames):
            due = start + k / rate
            while (now := time.monotonic()) < due:
                time.sleep(min(0.002, due - now))
            struct.pack_into('<q', payload, 0, time.monotonic_ns())
            channel.log(bytes(payload))
        latencies: List[int] = json.loads(client.stdout.readline())
        cpu = _cpu() - cpu0
    finally:
        client.kill()
        client.wait()
        channel.close()
        if gate is not None:
            gate.stop()
        server.stop()
    ms = sorted(v / 1e6 for v in latencies)
    delivered_mb = len(ms) * size / 1e6
    return {'gated': gated, 'rate': rate, 'size': size, 'frames': frames,
            'delivered': len(ms), 'median_ms': statistics.median(ms) if ms else float('nan'),
            'p99_ms': ms[min(len(ms) - 1, int(0.99 * len(ms)))] if ms else float('nan'),
            'cpu_s_per_mb': cpu / delivered_mb if delivered_mb else float('nan')}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--seconds', type=float, default=4.0)
    args = parser.parse_args()
    cases = [(30.0, 640 * 480 * 3), (15.0, 320 * 240 * 3), (120.0, 320 * 240 * 3)]
    runs: List[Dict] = []
    for _ in range(args.repeats):
        for rate, size in cases:
            for gated in (False, True):                 # (interleaved)
                runs.append(run_once(gated, rate, int(rate * args.seconds), size))
    print('| frames | rate [Hz] | path | delivered | median latency [ms] | p99 [ms] | '
          'server CPU [ms/MB] |')
    print('|---|---|---|---|---|---|---|')
    summary = []
    for rate, size in cases:
        row = {}
        for gated in (False, True):
            mine = [r for r in runs if r['rate'] == rate and r['size'] == size
                    and r['gated'] == gated]
            figures = {key: statistics.median(r[key] for r in mine)
                       for key in ('delivered', 'median_ms', 'p99_ms', 'cpu_s_per_mb')}
            row['gate' if gated else 'direct'] = figures
            print(f'| {size // 1000} kB | {rate:g} | {"gate" if gated else "direct"} | '
                  f'{figures["delivered"]:.0f} of {mine[0]["frames"]} | '
                  f'{figures["median_ms"]:.2f} | {figures["p99_ms"]:.2f} | '
                  f'{1e3 * figures["cpu_s_per_mb"]:.2f} |')
        ratio = row['gate']['cpu_s_per_mb'] / row['direct']['cpu_s_per_mb']
        extra = row['gate']['median_ms'] - row['direct']['median_ms']
        print(f'  {size // 1000} kB at {rate:g} Hz: gate/direct server CPU per MB {ratio:.2f}, '
              f'median latency +{extra:.2f} ms')
        summary.append({'rate': rate, 'size': size, **row, 'cpu_ratio': ratio,
                        'latency_added_ms': extra})
    out = HERE / 'results'
    out.mkdir(exist_ok=True)
    (out / 'live_view.json').write_text(json.dumps({'runs': runs, 'summary': summary},
                                                   indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
