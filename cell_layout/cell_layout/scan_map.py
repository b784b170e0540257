"""The map each youBot's laser scanner is matched to (no ROS): the faces of the world's fixed
obstacles that reach the scanner's height, and each scanner's localizer
(controllers.scan_localizer)."""
from __future__ import annotations

from typing import Any, Dict, List, Tuple

from cell_layout.fleet_routes import YOUBOT_HALF_LENGTH_M, YOUBOT_HALF_WIDTH_M, obstacle_height
from controllers.scan_localizer import (
    DRIFT_PER_M,
    ScanLocalizer,
    WallBox,
    WallMap,
    polygon_box,
)

# Scan points this close to the base's own footprint are its own (its wheels) [m].
BODY_MARGIN_M = 0.03


def walls_at(obstacles: List[Any], height: float) -> WallMap:
    """The faces of the obstacles (world_description's ObstacleConfig) that a scanner
    ``height`` [m] above the floor sees: those it can collide with whose extent in z spans it."""
    boxes, polygons = [], []
    for o in obstacles:
        half_h = obstacle_height(o) / 2
        if not o.collision or not (o.position[2] - half_h <= height <= o.position[2] + half_h):
            continue
        centre = (o.position[0], o.position[1])
        if o.shape == 'box':
            boxes.append(WallBox(centre, (o.size[0] / 2, o.size[1] / 2), o.yaw))
        else:                                   # a cylinder, or a sphere's section (its box)
            polygons.append(polygon_box(centre, o.size[0]))
    return WallMap(boxes, polygons)


def localizers(world: Any, base_z: Dict[str, float], drift: float = DRIFT_PER_M
               ) -> Dict[str, Tuple[ScanLocalizer, float]]:
    """A localizer for each robot of the world with a laser scanner (its ``laser``) among
    ``base_z`` (robot: its base_link's height above the floor [m]), and the scanner's rate
    [Hz]; ``drift``: how far the odometry may drift, per metre and per radian."""
    out = {}
    for robot in world.robots:
        laser = robot.laser
        if laser is None or robot.name not in base_z:
            continue
        walls = walls_at(list(world.obstacles), base_z[robot.name] + laser.z)
        out[robot.name] = (ScanLocalizer(
            walls, (laser.x, laser.y, laser.yaw),
            (YOUBOT_HALF_LENGTH_M + BODY_MARGIN_M, YOUBOT_HALF_WIDTH_M + BODY_MARGIN_M),
            drift), laser.rate)
    return out
