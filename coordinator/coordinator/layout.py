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
class UnloadStand:
    """Where the youBot stands, side-on to the pool, to unload one row of its plate: the arm
    turns only a quarter of the way round between that row and the pool (the far row would take
    it the long way round the front, as joint 1 cannot pass straight back)."""
    name: str
    pose: Pose2D
    row: int                            # the plate row unloaded here: +1 left (y > 0), -1 right
    drops: Tuple[np.ndarray, ...]       # release points of pool materials, one each (world)
    platform: bool = False              # the platform's place is in reach from here


@dataclass(frozen=True)
class CellLayout:
    belt_y: float                       # the belt's centre line (world y) [m]
    belt_top: float                     # its top surface (world z) [m]
    belt_end_x: float                   # the belt's downstream end (its stop's face) [m]
    belt_speed: float                   # nominal carrying speed [m/s]
    belt_width: float                   # [m]
    material_size: float                # cube edge [m]
    manifest: Dict[str, int]            # materials per colour in the batch
    ground_target: np.ndarray           # purple materials: a point on the floor (world)
    youbot_home: Pose2D                 # the youBot's start (and loading) pose
    youbot_base_z: float                # its base_link above the floor, on its wheels [m]
    zu12_base: Tuple[float, float, float, float]   # x, y, z, yaw
    platform_place: np.ndarray = field(default_factory=lambda: np.zeros(3))  # blue: surface
    # Where the youBot stands to unload (the right row, then the left row and the platform),
    # and the key poses of its paths: out, between the stands (it turns about clear of the
    # pool's wall), and back.
    stands: Tuple[UnloadStand, ...] = ()
    via_out: Tuple[Tuple[float, ...], ...] = ()
    via_turn: Tuple[Tuple[float, ...], ...] = ()
    via_back: Tuple[Tuple[float, ...], ...] = ()
    end_stop: bool = False              # materials accumulate at the end instead of falling off

    @property
    def total(self) -> int:
        return sum(self.manifest.values())

    def plate_bound(self) -> int:
        """Materials the Zu 12 puts on the youBot (all but purple)."""
        return sum(n for color, n in self.manifest.items() if color != 'purple')

    def stand(self, name: str) -> UnloadStand:
        return next(st for st in self.stands if st.name == name)

    def stand_for(self, color: str, slot: int) -> UnloadStand:
        """Where a material on plate slot ``slot`` is unloaded: the platform's stand for blue,
        otherwise the stand of the slot's row."""
        if self.destination(color) == 'platform':
            return next(st for st in self.stands if st.platform)
        return next(st for st in self.stands if st.row == slot_row(slot))

    def slot_order(self, color: str) -> List[int]:
        """The plate slots in the order the Zu 12 fills them for a material of ``color``: the
        row unloaded where it goes first (blue: the platform's row; pool materials: the first
        stand's row), the near slots first."""
        first = (self._platform_row() if self.destination(color) == 'platform'
                 else self.stands[0].row)
        return sorted(range(len(PLATE_SLOTS_IN_BASE_M)), key=lambda k: (slot_row(k) != first, k))

    def free_slots(self, color: str, taken: Dict[int, str]) -> List[int]:
        """The free plate slots for a material of ``color``, in the order they are filled
        (``slot_order``), with the slots ``taken`` (slot: colour of what is on it). A pool
        material leaves the platform row's last free slots to the manifest's platform
        materials not on the plate yet: with four oranges ahead of the blue, the blue went
        into the other row, and was unloaded there from the platform's stand, the arm going the
        long way round (a trial took 72.4 s against 65 s)."""
        free = [k for k in self.slot_order(color) if k not in taken]
        if self.destination(color) == 'platform' or not self.stands:
            return free
        platform = sum(n for c, n in self.manifest.items() if self.destination(c) == 'platform')
        to_come = platform - sum(1 for c in taken.values() if self.destination(c) == 'platform')
        in_row = [k for k in free if slot_row(k) == self._platform_row()]
        kept = set(in_row[max(0, len(in_row) - to_come):]) if to_come > 0 else set()
        return [k for k in free if k not in kept]

    def _platform_row(self) -> int:
        return next(st for st in self.stands if st.platform).row

    def destination(self, color: str) -> str:
        return {'purple': 'ground_target', 'orange': 'pool', 'blue': 'platform'}.get(
            color, 'pool')


def slot_row(slot: int) -> int:
    """The plate row of a slot: +1 left (y > 0), -1 right."""
    return 1 if PLATE_SLOTS_IN_BASE_M[slot][1] > 0.0 else -1


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
    """The layout of a loaded WorldConfig (world_description.world_config) of the pipeline cell."""
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
    # The youBot unloads from two stands west of the pool, side-on to it (Mecanum: it can stand
    # any way round): facing south (the pool on its left, the platform ahead on the left) for
    # the left row of its plate and the platform, then facing north (the pool on its right) for
    # the right row. Its wheels (0.209 m from base_link; its side 0.18 m) stay 3.1 cm off the
    # pool's west wall (its face 2 cm inside wall_x): at 2.1 cm, the base's overshoot on a
    # loaded machine touched it (real time: 1.5 cm and 3 degrees past the stand); each
    # centimetre further costs a run about 0.25 s (the arm reaches further). Each
    # orange has its own drop spot, 7-15 cm inside the wall and 10 cm from the next: a cube
    # dropped onto another can tumble back over the wall.
    wall_x = px - half
    side_x = wall_x - 0.26
    top = platform.position[2] + platform.size[2] / 2
    place = np.array([platform.position[0] - platform.size[0] / 2 + 0.05, platform.position[1],
                      top])
    right = UnloadStand('pool_right', (side_x, py + 0.05, math.pi / 2), -1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, 0.18), (0.07, 0.08), (0.15, 0.13), (0.07, -0.02))))
    left = UnloadStand('pool_left', (side_x, py - 0.3, -math.pi / 2), 1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, -0.22), (0.07, -0.15), (0.15, -0.2), (0.15, -0.12))), platform=True)
    home = (yb.x, yb.y, yb.yaw)
    return CellLayout(
        belt_y=conv.position[1], belt_top=conv.position[2],
        belt_end_x=conv.position[0] + conv.length / 2, belt_speed=conv.belt_speed,
        belt_width=conv.width,
        end_stop=conv.end_stop,
        material_size=size, manifest=dict(world.materials.counts),
        ground_target=np.array([named['ground_target'].position[0],
                                named['ground_target'].position[1], 0.0]),
        youbot_home=home, youbot_base_z=yb.z, zu12_base=(zu.x, zu.y, zu.z, zu.yaw),
        platform_place=place,
        stands=(left, right),
        # Out: down to the first stand from the north-west (never east of it, so never
        # nearer the wall), facing south as it parks: through a point 15 cm west of it, from
        # which the path comes in along the wall (from 10 cm, it bowed 1 cm past the stand
        # towards the wall, and 2 cm more with 0.2 s of delay between odometry and command);
        # between the stands it turns about 0.3 m off the wall (its corners sweep 0.34 m
        # about base_link); back home it turns round on the way.
        via_out=((side_x - 0.15, py + 0.55, -math.pi / 2),),
        via_turn=((side_x - 0.3, py - 0.12, 0.0),),
        via_back=((0.5 * (home[0] + side_x), 0.5 * (home[1] + right.pose[1]), 0.0),))
