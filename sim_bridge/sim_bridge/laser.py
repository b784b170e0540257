"""A planar laser scanner on a mobile base (no ROS): PyBullet casts its rays from the mount
(world_schema's LaserConfig) in the base's pose as it is, tilt included, and reports each
range with its noise. The noise is drawn from the world's seed, the robot and the scan's time
only, so a lock-step run reads the same scans every time, whoever listens."""
from __future__ import annotations

import math
import zlib

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from sim_bridge.sensors import Transform
from world_description.world_schema import LaserConfig


class LaserScanner:
    def __init__(self, client: BulletClient, config: LaserConfig, robot: str,
                 seed: int) -> None:
        self.config, self._p = config, client
        self._key = (int(seed) & 0xFFFFFFFF, zlib.crc32(robot.encode()))
        c = config
        self.angles = c.yaw + np.linspace(-c.fov / 2, c.fov / 2, c.rays)
        # Each ray's direction and the mount, in base_link.
        self._dirs = np.stack([np.cos(self.angles), np.sin(self.angles),
                               np.zeros(c.rays)], axis=1)
        self._mount = np.array([c.x, c.y, c.z])

    @property
    def angle_increment(self) -> float:
        c = self.config
        return c.fov / (c.rays - 1)

    def scan(self, base_link: Transform, time_ns: int) -> np.ndarray:
        """The ranges [m] of one scan, the base_link at ``base_link`` (world), at ``time_ns``:
        each the first hit along its ray, with noise, within [range_min, range_max]; +inf where
        nothing is within range_max."""
        c, p = self.config, self._p
        rot = np.array(p.getMatrixFromQuaternion(base_link[1])).reshape(3, 3)
        origin = np.asarray(base_link[0]) + rot @ self._mount
        dirs = self._dirs @ rot.T
        starts = origin + c.range_min * dirs
        ends = origin + c.range_max * dirs
        hits = p.rayTestBatch(starts.tolist(), ends.tolist())
        fraction = np.array([h[2] if h[0] >= 0 else math.inf for h in hits])
        ranges = c.range_min + fraction * (c.range_max - c.range_min)
        if c.noise > 0.0:
            rng = np.random.default_rng((*self._key, int(time_ns)))
            ranges = ranges + c.noise * rng.standard_normal(c.rays)
        hit = np.isfinite(ranges)
        ranges[hit] = np.clip(ranges[hit], c.range_min, c.range_max)
        return ranges
