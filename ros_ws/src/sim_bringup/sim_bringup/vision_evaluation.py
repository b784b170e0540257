"""Accuracy of the vision core on frames rendered by the simulator, against PyBullet's ground
truth, with seeded random placements, belt speeds, lighting and colour noise (the measure of
the vision benchmark and its test)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Set, Tuple

import numpy as np

from controllers.arrays import Vector
from perception.projection import CameraModel
from perception.segmentation import classes_of
from perception.vision import MaterialVision
from sim_bridge.world import SimWorld
from world_description.camera_geometry import look_at_rotation
from world_description.resources import resolve_resource
from world_description.world_config import CameraConfig, load_world

WORLD = 'package://world_description/worlds/pipeline_cell.yaml'


@dataclass
class Accuracy:
    frames: int = 0
    visible: int = 0               # (frame, material) pairs fully in view
    identified: int = 0            # ... observed once, with the right colour, within 5 mm
    false_colours: int = 0         # observations whose nearest material has another colour
    spurious: int = 0              # observations more than 1 cm from every material
    errors_m: List[float] = field(default_factory=list)
    latencies_s: List[float] = field(default_factory=list)
    # (run, track id) -> the indices of the materials it was nearest to
    tracks: Dict[Tuple[int, int], Set[int]] = field(default_factory=dict)

    @property
    def identification_rate(self) -> float:
        return self.identified / self.visible if self.visible else 0.0


def noisy(rgb: np.ndarray, rng: np.random.Generator, strength: float) -> np.ndarray:
    """Colour noise: per-channel gains, a brightness change and pixel noise."""
    if strength <= 0.0:
        return rgb
    gains = rng.uniform(1 - 0.15 * strength, 1 + 0.15 * strength, 3)
    brightness = rng.uniform(1 - 0.35 * strength, 1 + 0.25 * strength)
    out = rgb.astype(np.float32) * gains * brightness
    out += rng.normal(0.0, 6.0 * strength, rgb.shape)
    return np.clip(out, 0, 255).astype(np.uint8)


def random_lighting(rng: np.random.Generator) -> Dict[str, Any]:
    direction = rng.normal(size=3)
    direction[2] = abs(direction[2]) + 0.5
    return {'lightDirection': (direction / np.linalg.norm(direction)).tolist(),
            'lightColor': rng.uniform(0.8, 1.0, 3).tolist(),
            'lightAmbientCoeff': float(rng.uniform(0.4, 0.8)),
            'lightDiffuseCoeff': float(rng.uniform(0.2, 0.6)),
            'lightSpecularCoeff': float(rng.uniform(0.0, 0.1))}


def evaluate(runs: int, frames_per_run: int, seed: int = 0, noise: float = 1.0) -> Accuracy:
    """``runs`` scenarios, each with its own seed, belt speed (0.05..0.3 m/s) and lighting,
    followed for ``frames_per_run`` camera frames (15 Hz) once materials reach the view."""
    rng = np.random.default_rng(seed)
    acc = Accuracy()
    config = load_world(resolve_resource(WORLD))
    for run in range(runs):
        world = SimWorld(config, scenario_seed=int(rng.integers(0, 2**31 - 1)))
        try:
            _run(world, rng, frames_per_run, noise, acc, run)
        finally:
            world.close()
    return acc


def _run(world: SimWorld, rng: np.random.Generator, frames: int, noise: float, acc: Accuracy,
         run: int) -> None:
    camera = world.cameras[0]
    c, source, conveyor = camera.config, world.source, world.conveyor
    if source is None or conveyor is None or c.position is None or c.look_at is None:
        raise ValueError('the vision evaluation needs a world with a belt, materials and a '
                         'fixed camera')
    model = CameraModel(np.asarray(camera.intrinsics.k, float).reshape(3, 3),
                        look_at_rotation(c.position, c.look_at), np.asarray(c.position))
    size = source.config.size
    vision = MaterialVision(model, c.width, c.height, conveyor.top[2], size,
                            classes_of(source.config), yaw=conveyor.config.yaw)
    conveyor.speed = float(rng.uniform(0.05, 0.3))
    lighting = random_lighting(rng)
    steps = round(1.0 / 15.0 / world.time_step)
    # Run the belt until the first material reaches the view.
    while not world.materials or source.pose(world.materials[0])[0][0] < -0.95:
        world.step()
    for _ in range(frames):
        for _ in range(steps):
            world.step()
        rgb = noisy(world.render(camera, lighting)[..., :3].copy(), rng, noise)
        start = time.perf_counter()
        result = vision.process(world.sim_time, rgb)
        acc.latencies_s.append(time.perf_counter() - start)
        acc.frames += 1
        truth = {m.index: (m.color, source.pose(m)[0]) for m in world.materials}
        seen = {i for i, (_, p) in truth.items() if _fully_in_view(model, p, size, c)}
        matched = set()
        for obs in result.observations:
            dists = {i: float(np.linalg.norm(p[:2] - obs.position[:2]))
                     for i, (_, p) in truth.items()}
            nearest = min(dists, key=lambda i: dists[i])
            if dists[nearest] > 0.01:
                acc.spurious += 1
                continue
            if obs.color != truth[nearest][0]:
                acc.false_colours += 1
                continue
            acc.errors_m.append(dists[nearest])
            if dists[nearest] < 0.005 and nearest in seen and nearest not in matched:
                matched.add(nearest)
        acc.visible += len(seen)
        acc.identified += len(matched & seen)
        for track in result.tracks:
            p = track.position
            nearest = min(truth, key=lambda i: float(np.linalg.norm(truth[i][1][:2] - p[:2])))
            acc.tracks.setdefault((run, track.id), set()).add(nearest)


def _fully_in_view(model: CameraModel, centre: Vector, size: float, c: CameraConfig) -> bool:
    h = size / 2
    corners = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])
    px = model.project(corners + centre)
    margin = 3
    return bool(np.all(px[:, 0] >= margin) and np.all(px[:, 0] <= c.width - 1 - margin)
                and np.all(px[:, 1] >= margin) and np.all(px[:, 1] <= c.height - 1 - margin))
