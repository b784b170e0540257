"""A robot's ``laser`` entry: the planar laser scanner on a mobile base (world_schema's
LaserConfig)."""
from __future__ import annotations

import math
from typing import Any

from world_description.world_schema import LaserConfig, Reader

# A mount further than this from base_link is not on the base [m].
MOUNT_REACH_M = 2.0


def laser_section(r: Reader, item: Any, where: str) -> LaserConfig:
    r.only(item, where, {'x', 'y', 'z', 'yaw', 'fov', 'rays', 'range_min', 'range_max', 'rate',
                         'noise'})
    d = LaserConfig()
    mount = {k: r.number(item, k, where, default=getattr(d, k), lo=-MOUNT_REACH_M,
                         hi=MOUNT_REACH_M) for k in ('x', 'y', 'z')}
    laser = LaserConfig(
        **mount,
        yaw=r.number(item, 'yaw', where, default=d.yaw, lo=-math.pi, hi=math.pi),
        fov=r.number(item, 'fov', where, default=d.fov, lo=0.01, hi=2.0 * math.pi),
        rays=int(r.number(item, 'rays', where, default=d.rays, lo=2, hi=4096, integer=True)),
        range_min=r.number(item, 'range_min', where, default=d.range_min, lo=0.0, hi=10.0),
        range_max=r.number(item, 'range_max', where, default=d.range_max, lo=0.05, hi=100.0),
        rate=r.number(item, 'rate', where, default=d.rate, lo=0.5, hi=100.0),
        noise=r.number(item, 'noise', where, default=d.noise, lo=0.0, hi=0.5))
    if laser.range_min >= laser.range_max:
        raise r.fail(where, 'range_min', f'must be below range_max ({laser.range_max}), got '
                     f'{laser.range_min}')
    return laser
