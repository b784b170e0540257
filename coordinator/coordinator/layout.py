"""Where things are in the pipeline cell, read from the world file (no ROS).

The coordinator knows the cell as a plant engineer would: the belt, the ground target, the
youBot's home pose and load plate, the pool and its platform, and the batch manifest (how many
materials of which colour). It never reads the simulator's ground truth to act.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Tuple

import numpy as np

from controllers.bezier import Pose2D

# The youBot's load plate: its top face above base_link [m] (plate_joint z + its thickness) and
# the slots the Zu 12 fills, in base_link. The youBot's arm cannot turn straight back (joint 1
# stops at 169 deg), so the slots sit in two rows along the plate's sides.
PLATE_TOP_IN_BASE_M = 0.046 + 0.01
PLATE_SLOTS_IN_BASE_M: Tuple[Tuple[float, float], ...] = tuple(
    (x, y) for x in (-0.065, -0.125, -0.185, -0.245) for y in (0.11, -0.11))


class LayoutError(ValueError):
    pass


@dataclass(frozen=True)
class CellLayout:
    belt_y: float                       # the belt's centre line (world y) [m]
    belt_top: float                     # its top surface (world z) [m]
    belt_end_x: float                   # where materials fall off [m]
    belt_speed: float                   # nominal carrying speed [m/s]
    material_size: float                # cube edge [m]
    manifest: Dict[str, int]            # materials per colour in the batch
    ground_target: np.ndarray           # purple materials: a point on the floor (world)
    youbot_home: Pose2D                 # the youBot's start (and loading) pose
    zu12_base: Tuple[float, float, float, float]   # x, y, z, yaw
    pool_drops: List[np.ndarray] = field(default_factory=list)  # orange: release points (world)
    platform_place: np.ndarray = field(default_factory=lambda: np.zeros(3))  # blue: surface
    # Where the youBot stands to unload into the pool and onto the platform, and the key
    # points of its paths there and back.
    pool_stand: Pose2D = (0.0, 0.0, 0.0)
    platform_stand: Pose2D = (0.0, 0.0, 0.0)
    via_out: Tuple[Tuple[float, float], ...] = ()
    via_back: Tuple[Tuple[float, float], ...] = ()

    @property
    def total(self) -> int:
        return sum(self.manifest.values())

    def plate_bound(self) -> int:
        """Materials the Zu 12 puts on the youBot (all but purple)."""
        return sum(n for color, n in self.manifest.items() if color != 'purple')

    def destination(self, color: str) -> str:
        return {'purple': 'ground_target', 'orange': 'pool', 'blue': 'platform'}.get(
            color, 'pool')


def slot_in_world(pose: Pose2D, slot: Tuple[float, float], base_z: float,
                  size: float) -> np.ndarray:
    """The plate surface point of a slot (where a material's bottom rests), in the world."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * slot[0] - s * slot[1], y + s * slot[0] + c * slot[1],
                     base_z + PLATE_TOP_IN_BASE_M])


def world_to_base(pose: Pose2D, point) -> np.ndarray:
    """A world point in the frame of a base at ``pose`` (planar: z unchanged)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = point[0] - x, point[1] - y
    return np.array([c * dx + s * dy, -s * dx + c * dy, point[2]])


def layout_from_world(world) -> CellLayout:
    """The layout of a loaded WorldConfig (sim_bridge.world_config) of the pipeline cell."""
    if world.conveyor is None or world.materials is None:
        raise LayoutError('the world has no conveyor with materials')
    named = {o.name: o for o in world.obstacles if o.name}
    for needed in ('ground_target', 'pool_floor', 'pool_platform'):
        if needed not in named:
            raise LayoutError(f'the world has no obstacle named {needed}')
    names = {r.name for r in world.robots}
    if not {'zu12', 'youbot'} <= names:
        raise LayoutError(f'the cell needs robots zu12 and youbot, the world has {sorted(names)}')
    conv = world.conveyor
    if abs(math.sin(conv.yaw)) > 1e-9 or math.cos(conv.yaw) < 0.0:
        raise LayoutError('the coordinator expects the belt to carry along +x (yaw 0)')
    yb = world.robot('youbot').pose
    zu = world.robot('zu12').pose
    size = world.materials.size
    pool, platform = named['pool_floor'], named['pool_platform']
    px, py = pool.position[0], pool.position[1]
    half = min(pool.size[0], pool.size[1]) / 2
    # The youBot stands west of the pool, facing it; it drops oranges over the west wall, each
    # at its own spot (two rows of three, 8-10 cm apart: a cube dropped onto another can tumble
    # back over the wall), and sets the blue down on the platform's near (west) half.
    stand_x = px - half - 0.38
    pool_stand = (stand_x, py - 0.1, 0.0)
    drops = [np.array([px - half + dx, py - 0.1 + dy, 0.2]) for dx in (0.08, 0.16)
             for dy in (0.0, 0.1, -0.1)]
    top = platform.position[2] + platform.size[2] / 2
    place = np.array([platform.position[0] - platform.size[0] / 2 + 0.05, platform.position[1],
                      top])
    # Its front (0.285 m ahead of base_link) stays west of the pool's west wall on the way.
    platform_stand = (place[0] - 0.475, platform.position[1], 0.0)
    home = (yb.x, yb.y, yb.yaw)
    return CellLayout(
        belt_y=conv.position[1], belt_top=conv.position[2],
        belt_end_x=conv.position[0] + conv.length / 2, belt_speed=conv.belt_speed,
        material_size=size, manifest=dict(world.materials.counts),
        ground_target=np.array([named['ground_target'].position[0],
                                named['ground_target'].position[1], 0.0]),
        youbot_home=home, zu12_base=(zu.x, zu.y, zu.z, zu.yaw), pool_drops=drops,
        platform_place=place, pool_stand=pool_stand, platform_stand=platform_stand,
        via_out=((0.5 * (home[0] + stand_x), 0.5 * (home[1] + pool_stand[1]) + 0.1),),
        via_back=((0.5 * (home[0] + stand_x), 0.5 * (home[1] + platform_stand[1])),))
