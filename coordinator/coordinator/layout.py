"""Where things are in the pipeline cell, read from the world file (no ROS).

The coordinator knows the cell as a plant engineer would: the belt, the youBot's home pose and
load plate, the pool and the stands it unloads from, the batch manifest (how many materials of
which class) and each class's rule: its destination (a region of the world, laid out in slots)
and its route there. It never reads the simulator's ground truth to act.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Dict, FrozenSet, List, Optional, Sequence, Set, Tuple

import numpy as np

from controllers.arrays import Vector
from controllers.bezier import Pose2D
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M

# The youBot's load plate: its top face above base_link [m] (plate_joint z + its thickness) and
# the slots the Zu 12 fills, in base_link. The youBot's arm cannot turn straight back (joint 1
# stops at 169 deg), so the slots sit in two rows along the plate's sides.
PLATE_TOP_IN_BASE_M = 0.046 + 0.01
# The plate's slots (base_link x, y): two rows, one each side, from the near end towards the back
# (the youBot's arm reaches no further), a material's size and PLATE_GAP_M apart but never
# nearer than PLATE_PITCH_MIN_M: four a row up to 50 mm (the paper's), three above.
PLATE_ROWS_Y_M = (0.11, -0.11)
PLATE_NEAR_X_M, PLATE_FAR_X_M = -0.065, -0.245
PLATE_PITCH_MIN_M = 0.06
# Carried materials stand at least this far apart on the youBot's plate [m]: with 6 mm between
# 54 mm materials, the Zu 12 knocked a neighbour as it set one down, and the youBot found no
# lift off the plate that kept clear of them.
PLATE_GAP_M = 0.01


def plate_grid(size: float) -> Tuple[Tuple[float, float], ...]:
    """The plate's slots for carried materials of edge ``size`` at most, in the order of
    their numbers (near to far, each with its left and right)."""
    pitch = max(PLATE_PITCH_MIN_M, size + PLATE_GAP_M)
    n = int(math.floor((PLATE_NEAR_X_M - PLATE_FAR_X_M) / pitch + 1e-9)) + 1
    return tuple((PLATE_NEAR_X_M - k * pitch, y) for k in range(n) for y in PLATE_ROWS_Y_M)


# The paper's plate (50 mm materials).
PLATE_SLOTS_IN_BASE_M = plate_grid(0.05)


# A destination's slots: a grid over its top face, the materials this far apart (and this far in
# from its edges) [m]. The pool's slots are the unload stands' drop spots instead.
SLOT_GAP_M = 0.02
SLOT_EDGE_M = 0.025
POOL = 'pool_floor'


class LayoutError(ValueError):
    pass


@dataclass(frozen=True)
class Rule:
    """A material class's rule: where it goes, and how (world_description.material_classes)."""
    name: str
    destination: str                    # a region: an obstacle of the world
    route: str                          # 'place' (by the Zu 12) or 'carry' (by the youBot)
    size: float                         # cube edge [m]
    mass: float                         # [kg]


@dataclass(frozen=True)
class Region:
    """A destination: an obstacle's top face, and the slots a material is set down on (the
    point under its centre), in the order they are taken. The pool's slots are release points
    over its floor (``drop``): a material is let go there, above the walls."""
    name: str
    center: Tuple[float, float]         # world x, y
    half: Tuple[float, float]           # half its footprint along x and y [m]
    top: float                          # its top face (world z)
    slots: Tuple[np.ndarray, ...]
    drop: bool = False

    def box(self, size: float) -> Tuple[float, ...]:
        """Where the centre of a material of edge ``size`` resting on it lies (x0, x1, y0, y1,
        z0, z1): on the face, not on another material."""
        (x, y), (hx, hy) = self.center, self.half
        return (x - hx, x + hx, y - hy, y + hy, self.top, self.top + size)


def slot_grid(center: Tuple[float, float], half: Tuple[float, float], top: float, size: float,
              first: Tuple[float, float]) -> Tuple[np.ndarray, ...]:
    """A grid of slots over a face, centred on it, nearest ``first`` (x, y) first."""
    pitch, margin = size + SLOT_GAP_M, size / 2 + SLOT_EDGE_M
    axes = []
    for c, h in zip(center, half):
        n = int(math.floor((2 * h - 2 * margin) / pitch + 1e-9)) + 1 if 2 * h >= 2 * margin else 0
        axes.append([c + (k - (n - 1) / 2) * pitch for k in range(n)])
    points = [np.array([x, y, top]) for x in axes[0] for y in axes[1]]
    return tuple(sorted(points, key=lambda p: (round(math.hypot(p[0] - first[0],
                                                                 p[1] - first[1]), 9),
                                                p[0], p[1])))


@dataclass(frozen=True)
class UnloadStand:
    """Where the youBot stands, side-on to the pool, to unload one row of its plate: the arm
    turns only a quarter of the way round between that row and the pool (the far row would take
    it the long way round the front, as joint 1 cannot pass straight back)."""
    name: str
    pose: Pose2D
    row: int                            # the plate row unloaded here: +1 left (y > 0), -1 right
    drops: Tuple[np.ndarray, ...]       # release points of pool materials, one each (world)
    serves: FrozenSet[str] = frozenset()     # the destinations unloaded from here
    # How far the base may stand from ``pose`` along its heading, back and forth [m]: its
    # footprint stays clear of the world's obstacles (stand_slide).
    slide: Tuple[float, float] = (0.0, 0.0)

    def abeam(self, point: Vector) -> Pose2D:
        """The stand's pose slid along its heading (within ``slide``) to bring the arm's base
        level with ``point`` (world x, y): the nearest it comes to the point. A heavy material
        the arm cannot hold out at the stand's far drops is let go abeam of its base."""
        x, y, yaw = self.pose
        c, s = math.cos(yaw), math.sin(yaw)
        arm_x = x + ARM_BASE_IN_BASE_LINK_M[0] * c
        arm_y = y + ARM_BASE_IN_BASE_LINK_M[0] * s
        along = (point[0] - arm_x) * c + (point[1] - arm_y) * s
        along = min(max(along, self.slide[0]), self.slide[1])
        return (x + along * c, y + along * s, yaw)


@dataclass(frozen=True)
class CellLayout:
    belt_y: float                       # the belt's centre line (world y) [m]
    belt_top: float                     # its top surface (world z) [m]
    belt_end_x: float                   # the belt's downstream end (its stop's face) [m]
    belt_speed: float                   # nominal carrying speed [m/s]
    belt_width: float                   # [m]
    material_size: float                # the largest class's cube edge [m]
    manifest: Dict[str, int]            # materials per class in the batch
    youbot_home: Pose2D                 # the youBot's start (and loading) pose
    youbot_base_z: float                # its base_link above the floor, on its wheels [m]
    zu12_base: Tuple[float, float, float, float]   # x, y, z, yaw
    rules: Dict[str, Rule] = field(default_factory=dict)        # per class
    regions: Dict[str, Region] = field(default_factory=dict)    # the classes' destinations
    # Where the youBot stands to unload (the right row, then the left row and the platform),
    # and the key poses of its paths: out, between the stands (it turns about clear of the
    # pool's wall), and back.
    stands: Tuple[UnloadStand, ...] = ()
    via_out: Tuple[Tuple[float, ...], ...] = ()
    via_turn: Tuple[Tuple[float, ...], ...] = ()
    via_back: Tuple[Tuple[float, ...], ...] = ()
    end_stop: bool = False              # materials accumulate at the end instead of falling off
    # The youBot plate's slots for the largest carried class (plate_grid).
    plate_slots: Tuple[Tuple[float, float], ...] = PLATE_SLOTS_IN_BASE_M

    @property
    def total(self) -> int:
        return sum(self.manifest.values())

    def plate_bound(self) -> int:
        """Materials the Zu 12 puts on the youBot (those its route carries)."""
        return sum(n for name, n in self.manifest.items() if self.carried(name))

    def rule(self, name: str) -> Rule:
        return self.rules[name]

    def carried(self, name: str) -> bool:
        """Whether the class rides on the youBot to its destination."""
        return self.rules[name].route == 'carry'

    def destination(self, name: str) -> str:
        return self.rules[name].destination

    def size_of(self, name: str) -> float:
        return self.rules[name].size

    def region_of(self, name: str) -> Region:
        return self.regions[self.rules[name].destination]

    def stand(self, name: str) -> UnloadStand:
        return next(st for st in self.stands if st.name == name)

    def way_out(self, stand: str) -> Tuple[Tuple[float, ...], ...]:
        """The via points of the drive from home to ``stand``: past the pool's north-west corner
        facing the way the first stand faces (``via_out``); to a stand facing the other way,
        through the point the base turns about between the stands (``via_turn``): turning past
        the corner, its corners swept 2.7 cm into the pool's wall, and the plate's materials
        slid 6 cm."""
        turn = self.stand(stand).pose[2] - self.via_out[0][2]
        if abs(math.remainder(turn, 2 * math.pi)) < math.pi / 2:
            return self.via_out
        return self.via_turn

    def serving(self, region: str) -> UnloadStand:
        """The stand a set-down destination is unloaded from (the pool: each stand, its row)."""
        return next(st for st in self.stands if region in st.serves)

    def stand_for(self, name: str, slot: int) -> UnloadStand:
        """Where a material on plate slot ``slot`` is unloaded: the pool's from the stand of the
        slot's row, any other destination's from the stand that reaches it."""
        if self.destination(name) != POOL:
            return self.serving(self.destination(name))
        return next(st for st in self.stands if st.row == self.slot_row(slot))

    def slot_order(self, name: str) -> List[int]:
        """The plate slots in the order the Zu 12 fills them for a material of class ``name``:
        the row unloaded where it goes first (the first stand's row for the pool, the serving
        stand's row for another destination), the near slots first."""
        first = (self.stands[0].row if self.destination(name) == POOL
                 else self.serving(self.destination(name)).row)
        return sorted(range(len(self.plate_slots)),
                      key=lambda k: (self.slot_row(k) != first, k))

    def free_slots(self, name: str, taken: Dict[int, str],
                   to_come: Optional[Dict[str, int]] = None) -> List[int]:
        """The free plate slots for a material of class ``name``, in the order they are filled
        (``slot_order``), with the slots ``taken`` (slot: class of what is on it). A pool
        material leaves the last free slots of a set-down destination's row to the materials
        for it not on the plate yet (``to_come`` per class; by default the manifest's less those
        on the plate): with four oranges ahead of the blue, the blue went into the other row,
        and was unloaded there from the platform's stand, the arm going the long way round (a
        trial took 72.4 s against 65 s)."""
        free = [k for k in self.slot_order(name) if k not in taken]
        if self.destination(name) != POOL or not self.stands:
            return free
        kept: Set[Any] = set()
        for row in {st.row for st in self.stands if st.serves - {POOL}}:
            bound = [c for c in self.manifest if self.carried(c) and self.destination(c) != POOL
                     and self.serving(self.destination(c)).row == row]
            coming = (sum(to_come[c] for c in bound) if to_come is not None else
                      sum(self.manifest[c] for c in bound)
                      - sum(1 for c in taken.values() if c in bound))
            in_row = [k for k in free if self.slot_row(k) == row]
            if coming > 0:
                kept |= set(in_row[max(0, len(in_row) - coming):])
        return [k for k in free if k not in kept]

    def slot_row(self, slot: int) -> int:
        """The plate row of a slot: +1 left (y > 0), -1 right."""
        return 1 if self.plate_slots[slot][1] > 0.0 else -1


def slot_in_world(pose: Pose2D, slot: Tuple[float, float], base_z: float,
                  size: float) -> np.ndarray:
    """The plate surface point of a slot (where a material's bottom rests), in the world."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * slot[0] - s * slot[1], y + s * slot[0] + c * slot[1],
                     base_z + PLATE_TOP_IN_BASE_M])


def world_to_base(pose: Pose2D, point: Vector) -> np.ndarray:
    """A world point in the frame of a base at ``pose`` (planar: z unchanged)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = point[0] - x, point[1] - y
    return np.array([c * dx + s * dy, -s * dx + c * dy, point[2]])


def with_extra_materials(world: Any, extra: Sequence[str]) -> Any:
    """The world (world_description.world_config.WorldConfig) with a batch larger by one
    material of each class named in ``extra`` (materials spawned beside the plan's)."""
    if not extra:
        return world
    if world.materials is None:
        raise LayoutError('extra materials: the world has no materials')
    known = {c.name for c in world.materials.classes}
    unknown = sorted(set(extra) - known)
    if unknown:
        raise LayoutError(f'extra materials {unknown}: no such class (classes: '
                          f'{", ".join(sorted(known))})')
    classes = tuple(replace(c, count=c.count + list(extra).count(c.name))
                    for c in world.materials.classes)
    return replace(world, materials=replace(world.materials, classes=classes))


def layout_from_world(world: Any) -> CellLayout:
    """The layout of a loaded WorldConfig (world_description.world_config) of the pipeline
    cell; a LayoutError (one line) for a cell whose rules cannot work."""
    if world.conveyor is None or world.materials is None:
        raise LayoutError('the world has no conveyor with materials')
    named = {o.name: o for o in world.obstacles if o.name}
    names = {r.name for r in world.robots}
    if not {'zu12', 'youbot'} <= names:
        raise LayoutError(f'the cell needs robots zu12 and youbot, the world has {sorted(names)}')
    if POOL not in named:
        raise LayoutError(f'the world has no obstacle named {POOL}: the youBot unloads from '
                          'stands beside the pool')
    conv = world.conveyor
    if abs(math.sin(conv.yaw)) > 1e-9 or math.cos(conv.yaw) < 0.0:
        raise LayoutError('the coordinator expects the belt to carry along +x (yaw 0)')
    yb = world.robot('youbot').pose
    zu = world.robot('zu12').pose
    mats = world.materials
    rules = {c.name: Rule(c.name, c.destination, c.route, c.size, c.mass) for c in mats.classes}
    stands = tuple(replace(st, slide=stand_slide(st.pose, world.obstacles, world.floor_size))
                   for st in _stands(named[POOL], rules))
    into_pool = sum(c.count for c in mats.classes if c.destination == POOL)
    # (A spare spot per stand: one the arm cannot reach as the base stands is swapped for it.)
    heaviest = max((c.mass for c in mats.classes if c.destination == POOL), default=0.0)
    stands = _pool_drops(stands, named[POOL], yb.z, into_pool + len(stands), heaviest)
    home = (yb.x, yb.y, yb.yaw)
    right = next(st for st in stands if st.row == -1)
    side_x, py = stands[0].pose[0], named[POOL].position[1]
    layout = CellLayout(
        belt_y=conv.position[1], belt_top=conv.position[2],
        belt_end_x=conv.position[0] + conv.length / 2, belt_speed=conv.belt_speed,
        belt_width=conv.width,
        end_stop=conv.end_stop,
        material_size=mats.largest, manifest=dict(mats.counts),
        youbot_home=home, youbot_base_z=yb.z, zu12_base=(zu.x, zu.y, zu.z, zu.yaw),
        rules=rules, stands=stands,
        plate_slots=plate_grid(max((r.size for r in rules.values() if r.route == 'carry'),
                                   default=0.0)),
        # Out: down to the first stand from the north-west (never east of it, so never
        # nearer the wall), facing south as it parks: through a point 15 cm west of it, from
        # which the path comes in along the wall (from 10 cm, it bowed 1 cm past the stand
        # towards the wall, and 2 cm more with 0.2 s of delay between odometry and command);
        # between the stands it turns about 0.3 m off the wall (its corners sweep 0.34 m
        # about base_link); back home it turns round on the way.
        via_out=((side_x - 0.15, py + 0.55, -math.pi / 2),),
        via_turn=((side_x - 0.3, py - 0.12, 0.0),),
        via_back=((0.5 * (home[0] + side_x), 0.5 * (home[1] + right.pose[1]), 0.0),))
    regions: Dict[str, Region] = {}
    served: Dict[str, Set[str]] = {}
    for dest in sorted({r.destination for r in rules.values()}):
        regions[dest], by = _region(layout, named[dest], dest)
        if by:
            served.setdefault(by, set()).add(dest)
    layout = replace(layout, regions=regions, stands=tuple(
        replace(st, serves=st.serves | frozenset(served.get(st.name, ()))) for st in stands))
    _check_capacity(layout)
    return layout


def _stands(pool: Any, rules: Dict[str, Rule]) -> Tuple[UnloadStand, ...]:
    """The youBot unloads from two stands west of the pool, side-on to it (Mecanum: it can stand
    any way round): facing south (the pool on its left) for the left row of its plate, then
    facing north (the pool on its right) for the right row. Its wheels (0.209 m from base_link;
    its side 0.18 m) stay 3.1 cm off the pool's west wall (its face 2 cm inside wall_x): at
    2.1 cm, the base's overshoot on a loaded machine touched it (real time: 1.5 cm and 3 degrees
    past the stand); each centimetre further costs a run about 0.25 s (the arm reaches further).
    Each pool material has its own drop spot, 7-15 cm inside the wall and 10 cm from the next:
    a cube dropped onto another can tumble back over the wall. A carried class's other
    destination (the paper's platform) is unloaded from the stand nearer it."""
    px, py = pool.position[0], pool.position[1]
    half = min(pool.size[0], pool.size[1]) / 2
    wall_x = px - half
    side_x = wall_x - 0.26
    right = UnloadStand('pool_right', (side_x, py + 0.05, math.pi / 2), -1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, 0.18), (0.07, 0.08), (0.15, 0.13), (0.07, -0.02))), frozenset({POOL}))
    left = UnloadStand('pool_left', (side_x, py - 0.3, -math.pi / 2), 1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, -0.22), (0.07, -0.15), (0.15, -0.2), (0.15, -0.12))), frozenset({POOL}))
    return (left, right)


# The youBot's footprint: half its length and half its width over the wheels, about
# base_link [m] (its box 0.57 x 0.36, the wheels' outer faces 0.209 from base_link).
YOUBOT_HALF_LENGTH_M, YOUBOT_HALF_WIDTH_M = 0.29, 0.21
# A stand's base slides along its heading at most this far either way [m], keeping this far
# from any obstacle ahead or behind, and this far to its sides (a stand beside the pool's wall
# has 3.1 cm there) [m]; an obstacle this low is driven over (a marked area on the floor) [m].
STAND_SLIDE_MAX_M = 0.5
STAND_SLIDE_STEP_M = 0.01
STAND_CLEAR_AHEAD_M, STAND_CLEAR_SIDE_M = 0.05, 0.01
OBSTACLE_LOW_M = 0.01


def stand_slide(pose: Pose2D, obstacles: Sequence[Any], floor_size: float
                ) -> Tuple[float, float]:
    """How far a base standing at ``pose`` may slide along its heading, back (negative) and
    forth, in STAND_SLIDE_STEP_M steps up to STAND_SLIDE_MAX_M, its footprint (with its
    clearances) clear of every obstacle that stands higher than OBSTACLE_LOW_M and on the
    floor; (0, 0) if it is not clear where it stands."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    half = (YOUBOT_HALF_LENGTH_M + STAND_CLEAR_AHEAD_M, YOUBOT_HALF_WIDTH_M + STAND_CLEAR_SIDE_M)
    boxes = [_footprint(o) for o in obstacles
             if o.collision and o.position[2] + _height(o) / 2 > OBSTACLE_LOW_M]

    def clear(along: float) -> bool:
        at = (x + along * c, y + along * s)
        if max(abs(at[0]), abs(at[1])) + math.hypot(*half) > floor_size / 2:
            return False
        return not any(_overlap((at, yaw, half), box) for box in boxes)

    if not clear(0.0):
        return (0.0, 0.0)
    ends = []
    for sign in (-1.0, 1.0):
        along = 0.0
        while along < STAND_SLIDE_MAX_M - 1e-9 and clear(sign * (along + STAND_SLIDE_STEP_M)):
            along = round(along + STAND_SLIDE_STEP_M, 6)
        ends.append(sign * along)
    return (ends[0], ends[1])


def _height(o: Any) -> float:
    return float(o.size[2] if o.shape == 'box' else o.size[-1] if o.shape == 'cylinder'
                 else 2 * o.size[0])


def _footprint(o: Any) -> Tuple[Tuple[float, float], float, Tuple[float, float]]:
    """An obstacle's outline on the floor: centre, yaw and half extents (a round one's
    bounding square)."""
    if o.shape == 'box':
        half = (o.size[0] / 2, o.size[1] / 2)
    else:
        half = (o.size[0], o.size[0])
    return ((o.position[0], o.position[1]), o.yaw, half)


def _overlap(a: Any, b: Any) -> bool:
    """Whether two rectangles (centre, yaw, half extents) overlap (separating axes)."""
    axes = []
    corners = []
    for (cx, cy), yaw, (hx, hy) in (a, b):
        u, v = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
        axes += [u, v]
        corners.append([np.array([cx, cy]) + i * hx * u + j * hy * v
                        for i in (-1, 1) for j in (-1, 1)])
    for axis in axes:
        pa = [float(p @ axis) for p in corners[0]]
        pb = [float(p @ axis) for p in corners[1]]
        if max(pa) <= min(pb) or max(pb) <= min(pa):
            return False
    return True


# The youBot grips a material's top face with its TCP this far above it (its fingertips reach
# 10.4 mm beyond it) [m].
GRASP_STANDOFF_M = 0.0104 + 0.002
# More drop spots in the pool, when a batch brings more than the stands' eight: a grid this far
# apart, this far in from its walls [m], each in the arm's reach from the nearer stand.
POOL_DROP_PITCH_M = 0.07
POOL_DROP_EDGE_M = 0.07
POOL_DROP_MARGIN_M = 0.03


def _pool_drops(stands: Tuple[UnloadStand, ...], pool: Any, base_z: float, needed: int,
                mass: float) -> Tuple[UnloadStand, ...]:
    """The stands with the drop spots their arm reaches: their own, and more after them
    (nearest the wall first) until the pool has ``needed``, none nearer than POOL_DROP_PITCH_M
    to another, each in reach from its stand with a margin (at a tilt of its own: what is let
    go over the pool need not stay level), the arm holding ``mass`` kg there at rest: from the
    stand, or from the base slid along its line abeam the spot (UnloadStand.abeam)."""
    seen: Dict[Tuple[str, float, float, float], bool] = {}

    def reached(stand: UnloadStand, point: np.ndarray, margin: float) -> bool:
        key = (stand.name, round(float(point[0]), 6), round(float(point[1]), 6), margin)
        if key not in seen:
            seen[key] = _youbot_reaches_from(stand, point, base_z, margin, mass)
        return seen[key]

    stands = tuple(replace(st, drops=tuple(d for d in st.drops if reached(st, d, 0.0)))
                   for st in stands)
    if all(len(st.drops) >= needed / len(stands) for st in stands):
        return stands
    # Too few: more spots after the stands' own; if that still leaves the pool short (a heavy
    # class is held out only near the wall), spots on a grid of their own instead.
    drops = _more_drops(stands, pool, needed, reached, {st.name: list(st.drops) for st in stands})
    if sum(len(d) for d in drops.values()) < needed:
        fresh = _more_drops(stands, pool, needed, reached, {st.name: [] for st in stands})
        if sum(len(d) for d in fresh.values()) > sum(len(d) for d in drops.values()):
            drops = fresh
    return tuple(replace(st, drops=tuple(drops[st.name])) for st in stands)


def _more_drops(stands: Tuple[UnloadStand, ...], pool: Any, needed: int, reached: Any,
                drops: Dict[str, List[np.ndarray]]) -> Dict[str, List[np.ndarray]]:
    """``drops`` (per stand) with spots added from a fine grid over the pool, the wall's side
    first (the arm's reach), until there are ``needed``: none nearer than POOL_DROP_PITCH_M to
    another, each for the stand with fewest that ``reached`` (stand, point, margin) it."""
    px, py = pool.position[0], pool.position[1]
    hx, hy = pool.size[0] / 2, pool.size[1] / 2
    step = POOL_DROP_PITCH_M / 4                 # (candidates on a finer grid, taken greedily)
    xs = np.arange(px - hx + POOL_DROP_EDGE_M, px + hx - POOL_DROP_EDGE_M + 1e-9, step)
    ys = np.arange(py - hy + POOL_DROP_EDGE_M, py + hy - POOL_DROP_EDGE_M + 1e-9, step)
    have = sum(len(d) for d in drops.values())
    for x in xs:
        for y in ys:
            if have >= needed:
                return drops
            point = np.array([x, y, 0.2])
            if any(np.linalg.norm(point[:2] - d[:2]) < POOL_DROP_PITCH_M - 1e-9
                   for ds in drops.values() for d in ds):
                continue
            # (A stand with fewer first, then the nearer.)
            for stand in sorted(stands, key=lambda st: (len(drops[st.name]),
                                                        abs(st.pose[1] - y))):
                if reached(stand, point, POOL_DROP_MARGIN_M):
                    drops[stand.name].append(point)
                    have += 1
                    break
    return drops


def _youbot_reaches_from(stand: UnloadStand, point: np.ndarray, base_z: float, margin: float,
                         mass: float, over: float = 0.06) -> bool:
    """Whether the youBot's arm reaches ``point`` (world) and ``over`` above it, from
    ``stand`` or slid along its line abeam the point: ``margin`` [m] further out from the arm's
    base too (the base stands a centimetre or two off its goal), and holding ``mass`` kg there
    at rest (within youbot_holds' share of each joint's effort)."""
    from coordinator.reach import youbot_reaches
    up = np.array([0.0, 0.0, over])
    poses = [stand.pose]
    if stand.abeam(point) != tuple(stand.pose):
        poses.append(stand.abeam(point))
    for pose in poses:
        local = world_to_base(pose, point)
        local[2] -= base_z
        out = local[:2] - np.asarray(ARM_BASE_IN_BASE_LINK_M[:2])
        out = np.append(out / max(np.linalg.norm(out), 1e-9) * margin, 0.0)
        if (youbot_reaches([local + out + up, local + out])
                and youbot_reaches([local + up, local], mass)):
            return True
    return False


def _check_plate_load(layout: CellLayout, name: str, size: float, mass: float) -> None:
    """A LayoutError unless the youBot's arm holds ``mass`` kg at rest (within youbot_holds'
    share of each joint's effort) over one of the plate's slots, where it lifts every carried
    material from: a load it cannot hold there it cannot unload anywhere."""
    from coordinator.reach import YOUBOT_LOAD_MAX, youbot_least_need
    best: Optional[Tuple[str, float, float]] = None
    for slot in layout.plate_slots:
        top = np.array([slot[0], slot[1], PLATE_TOP_IN_BASE_M + size])
        need = youbot_least_need([top + np.array([0.0, 0.0, 0.06]), top], mass)
        if need is not None and (best is None or need[1] / need[2] < best[1] / best[2]):
            best = need
    if best is not None and best[1] > YOUBOT_LOAD_MAX * best[2]:
        joint, torque, effort = best
        raise LayoutError(f'{name} materials ({mass:g} kg) are more than the youBot\'s arm '
                          f'holds at rest over its plate: {joint} needs {torque:.2f} N m there '
                          f'at best, and takes at most {YOUBOT_LOAD_MAX:.0%} of its '
                          f'{effort:g} N m (the rest accelerates it)')


def _region(layout: CellLayout, obstacle: Any, name: str) -> Tuple[Region, str]:
    """A destination's region and its slots, each checked in reach of the robot that sets a
    material down there (a LayoutError if none is), and the stand the youBot unloads there from
    (a carried class's destination other than the pool: the nearer stand)."""
    from coordinator.reach import zu12_reaches
    ox, oy, oz = obstacle.position
    if abs(math.sin(2 * obstacle.yaw)) > 1e-9:
        raise LayoutError(f'destination {name} is turned {math.degrees(obstacle.yaw):.0f} deg: '
                          'a destination lies along the world axes')
    hx, hy = obstacle.size[0] / 2, obstacle.size[1] / 2
    if abs(math.cos(obstacle.yaw)) < 0.5:
        hx, hy = hy, hx
    top = oz + obstacle.size[2] / 2
    bound = [r for r in layout.rules.values() if r.destination == name]
    size = max(r.size for r in bound)
    routes = {r.route for r in bound}
    if len(routes) > 1:
        raise LayoutError(f'destination {name} is reached by both routes '
                          f'({", ".join(r.name for r in bound)}): give it one')
    if name == POOL:
        if routes != {'carry'}:
            raise LayoutError(f'{POOL} is the youBot\'s: its materials are carried there '
                              '(route: carry)')
        drops = tuple(d for st in layout.stands for d in st.drops)
        return Region(name, (ox, oy), (hx, hy), top, drops, drop=True), ''

    if routes == {'place'}:
        slots = slot_grid((ox, oy), (hx, hy), top, size, (ox, oy))
        lift = size + 0.01
        slots = tuple(p for p in slots if zu12_reaches(
            layout.zu12_base, [p + np.array([0.0, 0.0, lift]),
                               p + np.array([0.0, 0.0, lift + 0.07])]))
        if not slots:
            raise LayoutError(f'destination {name} is out of the Zu 12\'s reach (its base at '
                              f'{layout.zu12_base[:2]})')
        return Region(name, (ox, oy), (hx, hy), top, slots), ''
    stand = min(layout.stands, key=lambda st: math.hypot(st.pose[0] - ox, st.pose[1] - oy))
    slots = slot_grid((ox, oy), (hx, hy), top, size, stand.pose[:2])
    # Each slot the arm sets the heaviest of its classes down on, holding it at rest (from the
    # stand, or from the base slid along its line abeam the slot).
    mass = max(r.mass for r in bound)
    reached = [p for p in slots if _youbot_reaches_from(
        stand, p + np.array([0.0, 0.0, size + 0.015]), layout.youbot_base_z, 0.0, mass, 0.05)]
    if not reached:
        light = mass > 0.0 and any(_youbot_reaches_from(
            stand, p + np.array([0.0, 0.0, size + 0.015]), layout.youbot_base_z, 0.0, 0.0, 0.05)
            for p in slots)
        raise LayoutError(f'destination {name} is out of the youBot arm\'s reach from its '
                          f'unload stands beside the pool' + (
                              f' holding {mass:g} kg at rest (it reaches it empty-handed)'
                              if light else ''))
    return Region(name, (ox, oy), (hx, hy), top, tuple(reached)), stand.name


# The largest material the youBot carries [m].
CARRIED_MAX_M = 0.06


def _check_capacity(layout: CellLayout) -> None:
    """Every destination has a slot for each material bound for it (the youBot makes as many
    trips as its load needs), every carried material fits the plate's slots, and the youBot's
    arm holds it at rest over one of them at least."""
    for name, rule in layout.rules.items():
        if rule.route == 'carry' and rule.size > CARRIED_MAX_M + 1e-9:
            raise LayoutError(f'{name} ({rule.size} m) is too large to be carried: the youBot '
                              f'carries materials of at most {CARRIED_MAX_M} m')
        if rule.route == 'carry' and rule.mass > 0.0:
            _check_plate_load(layout, name, rule.size, rule.mass)
    for name, region in layout.regions.items():
        bound = sum(n for c, n in layout.manifest.items() if layout.destination(c) == name)
        if bound > len(region.slots):
            raise LayoutError(f'destination {name} has {len(region.slots)} slots in reach for '
                              f'{bound} materials')
