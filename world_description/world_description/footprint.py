"""A cell seen from above: each obstacle's, the belt's and the robots' footprint on the floor, to
draw a map of the cell under paths (a report's, a comparison's)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Tuple

import numpy as np

from world_description.world_config import WorldConfig

BELT_RGBA = (0.35, 0.35, 0.35, 1.0)
ROBOT_RGBA = (0.2, 0.2, 0.2, 1.0)


@dataclass(frozen=True)
class Footprint:
    name: str
    outline: np.ndarray                   # (N, 2) x, y [m], a closed polygon
    rgba: Tuple[float, float, float, float]
    label: bool = True                    # big enough to be named on a map


def _box(cx: float, cy: float, sx: float, sy: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    corners = np.array([[-sx, -sy], [sx, -sy], [sx, sy], [-sx, sy]]) / 2
    outline: np.ndarray = corners @ np.array([[c, s], [-s, c]]) + (cx, cy)
    return outline


def _circle(cx: float, cy: float, r: float, n: int = 24) -> np.ndarray:
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack((cx + r * np.cos(a), cy + r * np.sin(a)))


def footprints(world: WorldConfig) -> List[Footprint]:
    """The cell's footprints, drawn in this order: obstacles (marked areas first), the belt,
    the robots at their start (a small disc)."""
    out = []
    for o in sorted(world.obstacles, key=lambda o: o.collision):
        x, y = o.position[0], o.position[1]
        if o.shape == 'box':
            outline = _box(x, y, o.size[0], o.size[1], o.yaw)
            big = min(o.size[0], o.size[1]) >= 0.1
        else:                                   # a cylinder or a sphere: radius first
            outline = _circle(x, y, o.size[0])
            big = o.size[0] >= 0.05
        out.append(Footprint(o.name, outline, o.color, bool(o.name) and big))
    if world.conveyor is not None:
        c = world.conveyor
        out.append(Footprint('belt', _box(c.position[0], c.position[1], c.length, c.width,
                                          c.yaw), BELT_RGBA))
    for robot in world.robots:
        out.append(Footprint(robot.name, _circle(robot.pose.x, robot.pose.y, 0.08),
                             ROBOT_RGBA))
    return out
