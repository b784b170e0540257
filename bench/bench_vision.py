"""Vision benchmark: accuracy of the vision core on simulator frames (seeded placements, belt
speeds, lighting and colour noise) against PyBullet's ground truth; per-frame latency; the
cost of rendering the belt camera. Prints the figures and writes bench/results/."""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from sim_bridge.world import SimWorld
from sim_bringup.vision_evaluation import WORLD, evaluate
from world_description.resources import resolve_resource
from world_description.world_config import load_world

HERE = Path(__file__).resolve().parent


def render_cost(frames: int) -> dict:
    world = SimWorld(load_world(resolve_resource(WORLD)))
    camera = world.cameras[0]
    for _ in range(2000):                   # materials on the belt
        world.step()
    timings = {}
    for backdrop in (False, True):          # the floor drawn in every frame: the baseline
        world.backdrops = backdrop
        world.render(camera)
        t0 = time.perf_counter()
        for _ in range(frames):
            world.render(camera)
        timings[backdrop] = (time.perf_counter() - t0) / frames
    per_frame = timings[True]
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        world.step()
    step = (time.perf_counter() - t0) / n
    world.close()
    c = camera.config
    return {'resolution': f'{c.width}x{c.height}', 'render_ms': per_frame * 1e3,
            'render_floor_drawn_ms': timings[False] * 1e3,
            'step_ms': step * 1e3, 'camera_rate_hz': c.rate,
            'render_share_at_rate': per_frame * c.rate / (per_frame * c.rate
                                                          + step / world.time_step)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument('--frames', type=int, default=150)
    args = parser.parse_args()
    acc = evaluate(args.runs, args.frames, seed=2026, noise=1.0)
    errors = np.array(acc.errors_m) * 1e3
    lat = np.array(acc.latencies_s) * 1e3
    per_material = {}
    for (run, _), materials in acc.tracks.items():
        for m in materials:
            per_material[(run, m)] = per_material.get((run, m), 0) + 1
    results = {
        'frames': acc.frames, 'visible': acc.visible, 'identified': acc.identified,
        'identification_rate': acc.identification_rate, 'false_colours': acc.false_colours,
        'spurious': acc.spurious, 'error_median_mm': float(np.median(errors)),
        'error_p99_mm': float(np.percentile(errors, 99)), 'error_max_mm': float(errors.max()),
        'latency_median_ms': float(np.median(lat)),
        'latency_p99_ms': float(np.percentile(lat, 99)),
        'frames_per_s': float(1e3 / np.mean(lat)),
        'tracks': len(acc.tracks), 'materials_tracked': len(per_material),
        'materials_with_one_track': sum(1 for v in per_material.values() if v == 1),
        'tracks_with_one_material': sum(1 for v in acc.tracks.values() if len(v) == 1),
        'render': render_cost(100)}
    r = results
    print(f'vision core, {args.runs} seeded scenarios x {args.frames} frames (belt 0.05-0.3 m/s, '
          'random lighting, colour noise):')
    print(f'  identification {100 * r["identification_rate"]:.2f} % ({r["identified"]}/'
          f'{r["visible"]} materials fully in view), false colours {r["false_colours"]}, '
          f'spurious {r["spurious"]}')
    print(f'  position error median {r["error_median_mm"]:.2f} mm, p99 {r["error_p99_mm"]:.2f} mm,'
          f' max {r["error_max_mm"]:.2f} mm')
    print(f'  tracks {r["tracks"]}: each one material: {r["tracks_with_one_material"]}; '
          f'materials with exactly one track: {r["materials_with_one_track"]}/'
          f'{r["materials_tracked"]}')
    print(f'  per-frame latency median {r["latency_median_ms"]:.2f} ms, p99 '
          f'{r["latency_p99_ms"]:.2f} ms ({r["frames_per_s"]:.0f} frames/s)')
    rc = r['render']
    print(f'belt camera {rc["resolution"]}: render {rc["render_ms"]:.1f} ms per frame (the floor '
          f'drawn in every frame: {rc["render_floor_drawn_ms"]:.1f} ms, ratio '
          f'{rc["render_floor_drawn_ms"] / rc["render_ms"]:.2f}), physics step '
          f'{rc["step_ms"]:.3f} ms; at {rc["camera_rate_hz"]:g} Hz rendering is '
          f'{100 * rc["render_share_at_rate"]:.0f} % of the simulation cost')
    out = HERE / 'results'
    out.mkdir(exist_ok=True)
    (out / 'bench_vision.json').write_text(json.dumps(results, indent=2))
    ok = (r['identification_rate'] >= 0.999 and r['false_colours'] == 0
          and r['error_max_mm'] < 5.0)
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
