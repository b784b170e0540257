"""Where things are in the pipeline cell (no ROS): the layout a world file gives it
(world_layout.py reads it).

The coordinator knows the cell as a plant engineer would: the belt, the youBot's home pose and
load plate, the pool and the stands it unloads from, the batch manifest (how many materials of
which class) and each class's rule: its destination (a region of the world, laid out in slots)
and its route there. It never reads the simulator's ground truth to act.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, FrozenSet, List, Optional, Sequence, Set, Tuple

import numpy as np

from cell_layout.arm_models import ARM_CONTROLLER as ARM_CONTROLLER  # (re-exported)
from cell_layout.arm_models import ArmModel
from controllers.arrays import Vector
from controllers.bezier import Pose2D
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M
from world_description.world_schema import LIFT_SWING_CLEARANCE_M, LINK_CLEARANCE_M

# The youBot's load plate: its top face above base_link [m] (plate_joint z + its thickness) and
# the slots the loader fills, in base_link. The youBot's arm cannot turn straight back (joint 1
# stops at 169 deg), so the slots sit in two rows along the plate's sides.
PLATE_TOP_IN_BASE_M = 0.046 + 0.01
# The youBot's arm upright (the datasheet's candle pose) while the base drives home, and while
# it waits there to be loaded.
YOUBOT_CARRY_Q = np.zeros(5)
# The plate's slots (base_link x, y): two rows, one each side, from the near end towards the back
# (the youBot's arm reaches no further), a material's size and PLATE_GAP_M apart but never
# nearer than PLATE_PITCH_MIN_M: four a row up to 50 mm (the paper's), three above.
PLATE_ROWS_Y_M = (0.11, -0.11)
PLATE_NEAR_X_M, PLATE_FAR_X_M = -0.065, -0.245
PLATE_PITCH_MIN_M = 0.06
# Carried materials stand at least this far apart on the youBot's plate [m]: with 6 mm between
# 54 mm materials, the loader knocked a neighbour as it set one down, and the youBot found no
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
# How far a resting material's centre may sink into, or stand off, what it rests on, as the
# simulator's contacts leave it [m].
RESTING_TOLERANCE_M = 0.002


class LayoutError(ValueError):
    pass


@dataclass(frozen=True)
class Rule:
    """A material class's rule: where it goes, and how (world_description.material_classes)."""
    name: str
    destination: str                    # a region: an obstacle of the world
    route: str                          # 'place' (by the loader) or 'carry' (by the youBot)
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
        z0, z1): on the face, not on another material. A cube that touches the face, however
        it lies (flat, on an edge, leaning), has its centre at most half its space diagonal
        over it; one higher rests on something else, such as another material."""
        (x, y), (hx, hy) = self.center, self.half
        return (x - hx, x + hx, y - hy, y + hy, self.top,
                self.top + size * math.sqrt(3.0) / 2.0 + RESTING_TOLERANCE_M)


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
    side: int = 0                       # the pool's side it stands at (PoolSide): 0 the west


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
class PoolSide:
    """The ways to and from the stands of one side of the pool: the via points out from the
    loading pose to the side's first stand (``out``) and to its other stand (``out_turn``),
    between its stands (``turn``), and the first ones of every way off it (``exit``: past the
    pool's corner), before the turn round on the way back (fleet_routes.way_back)."""
    out: Tuple[Tuple[float, ...], ...]
    out_turn: Tuple[Tuple[float, ...], ...]
    turn: Tuple[Tuple[float, ...], ...]
    exit: Tuple[Tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class CellRobot:
    """A robot of the cell as the controller talks to it: its name in the world, the
    namespace of its topics and services, its arm controller's joints in order, its grip
    tool's service, and its arm's model (kinematics and limits, from the world)."""
    name: str
    namespace: str
    joints: Tuple[str, ...]
    grip: str                           # absolute, e.g. /zu12/suction
    arm: Optional[ArmModel] = None

    def topic(self, name: str) -> str:
        """One of its topics or services, absolute."""
        return f'/{self.namespace}/{name}' if self.namespace else f'/{name}'

    @property
    def model(self) -> ArmModel:
        """Its arm's model (a robot of a layout read from a world has one)."""
        if self.arm is None:
            raise LayoutError(f'robot {self.name}: no arm model')
        return self.arm


@dataclass(frozen=True)
class CellLayout:
    belt_y: float                       # the belt's centre line (world y) [m]
    belt_top: float                     # its top surface (world z) [m]
    belt_end_x: float                   # the belt's downstream end (its stop's face) [m]
    belt_speed: float                   # nominal carrying speed [m/s]
    belt_width: float                   # [m]
    material_size: float                # the largest class's cube edge [m]
    manifest: Dict[str, int]            # materials per class in the batch
    youbot_home: Pose2D                 # where a youBot is loaded (the first one's start pose)
    youbot_base_z: float                # its base_link above the floor, on its wheels [m]
    # Who does what: the arm that loads from the belt (where its base stands: x, y, z, yaw),
    # and the robots that carry (a fleet of youBots), each with its start pose, where it waits
    # while another is loaded (``parks``, in order; none for a fleet of one: it starts where it
    # is loaded).
    loader: CellRobot
    loader_base: Tuple[float, float, float, float]
    transports: Tuple[CellRobot, ...]
    rules: Dict[str, Rule] = field(default_factory=dict)        # per class
    regions: Dict[str, Region] = field(default_factory=dict)    # the classes' destinations
    # Where the youBot stands to unload (the right row, then the left row and the platform),
    # and the key poses of its paths: out, between the stands (it turns about clear of the
    # pool's wall), and back.
    stands: Tuple[UnloadStand, ...] = ()
    via_out: Tuple[Tuple[float, ...], ...] = ()
    via_turn: Tuple[Tuple[float, ...], ...] = ()
    via_back: Tuple[Tuple[float, ...], ...] = ()
    parks: Tuple[Pose2D, ...] = ()
    # Two bases never come nearer than this, footprint to footprint [m]; a youBot sets off
    # with at most ``trip_load`` materials (0: as many as its plate holds).
    clearance: float = 0.1
    trip_load: int = 0
    # The pool's other sides a fleet unloads at (the first, the west, is via_out and via_turn's):
    # each youBot of a fleet has a side (side_of), so two youBots unload at once.
    more_sides: Tuple[PoolSide, ...] = ()
    # The conveyor drive's encoder: its resolution [m per count] (0: the cell has none).
    belt_encoder: float = 0.0
    # The belt's upstream end (world x) [m], and the most upstream x from which the loader
    # reaches a material to the belt's end (its pick window: loader_reach.py).
    belt_start_x: float = -math.inf
    pick_from: float = -math.inf
    # The world's fixed boxes (name, centre, half sizes, yaw), and how near the loader's links
    # may come to them and to the conveyor on its swings [m] (the world's cell.link_clearance;
    # below 0: not checked; link_clearance.py).
    fixed: Tuple[Tuple[str, Tuple[float, float, float], Tuple[float, float, float], float],
                 ...] = ()
    link_clearance: float = LINK_CLEARANCE_M

    @property
    def transport(self) -> CellRobot:
        """The first transport robot (the only one of the paper's cell)."""
        return self.transports[0]

    @property
    def fleet(self) -> bool:
        """Whether the youBots wait at parks of their own, apart from the loading pose, and
        share it and the pool by the fleet's rules: several youBots, or one that starts away
        from the loading pose (a fleet of one, as a sweep of the fleet's size makes)."""
        return bool(self.parks)

    @property
    def robots(self) -> Dict[str, CellRobot]:
        """The cell's robots with an arm, by name: the loader, then the transports."""
        return {r.name: r for r in (self.loader, *self.transports)}

    def park(self, robot: str) -> Pose2D:
        """Where transport ``robot`` starts, and waits while another is loaded."""
        if not self.parks:
            return self.youbot_home
        return self.parks[[r.name for r in self.transports].index(robot)]
    end_stop: bool = False              # materials accumulate at the end instead of falling off
    # What the loader's cup holds keeps this far from what is on the belt or at its end as it
    # swings on from a lift point [m] (the world's cell.swing_clearance).
    swing_clearance: float = LIFT_SWING_CLEARANCE_M
    # The youBot plate's slots for the largest carried class (plate_grid).
    plate_slots: Tuple[Tuple[float, float], ...] = PLATE_SLOTS_IN_BASE_M

    @property
    def total(self) -> int:
        return sum(self.manifest.values())

    def plate_bound(self) -> int:
        """Materials the loader puts on the youBot (those its route carries)."""
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

    def side_of(self, robot: str) -> int:
        """The side of the pool transport ``robot`` unloads at (pool_sides): the fleet's youBots
        take the sides in turn, in the cell's order (the paper's youBot, and any one not a
        transport: the west)."""
        names = [r.name for r in self.transports]
        return names.index(robot) % (1 + len(self.more_sides)) if robot in names else 0

    def stands_of(self, robot: str) -> Tuple[UnloadStand, ...]:
        """The stands transport ``robot`` unloads from, in the order it visits them."""
        side = self.side_of(robot)
        return tuple(st for st in self.stands if st.side == side)

    def way_out(self, stand: str) -> Tuple[Tuple[float, ...], ...]:
        """The via points of the drive from home to ``stand``: past the pool's corner facing
        the way its side's first stand faces (``out``; the west's ``via_out``); to a stand
        facing the other way, through the point the base turns about between the stands
        (``out_turn``; the west's ``via_turn``): turning past the corner, its corners swept
        2.7 cm into the pool's wall, and the plate's materials slid 6 cm."""
        st = self.stand(stand)
        side = pool_sides(self)[st.side]
        turn = st.pose[2] - side.out[0][2]
        if abs(math.remainder(turn, 2 * math.pi)) < math.pi / 2:
            return side.out
        return side.out_turn

    def serving(self, region: str) -> UnloadStand:
        """The stand a set-down destination is unloaded from (the pool: each stand, its row)."""
        return next(st for st in self.stands if region in st.serves)

    def stand_for(self, name: str, slot: int, robot: str = '') -> UnloadStand:
        """Where a material on transport ``robot``'s plate slot ``slot`` is unloaded: the
        pool's from the stand of the slot's row on the robot's side, any other destination's
        from the stand that reaches it."""
        if self.destination(name) != POOL:
            return self.serving(self.destination(name))
        side = self.side_of(robot)
        return next(st for st in self.stands if st.row == self.slot_row(slot)
                    and st.side == side)

    def slot_order(self, name: str, robot: str = '') -> List[int]:
        """The plate slots in the order the loader fills them for a material of class ``name``
        (on transport ``robot``'s plate): the row unloaded where it goes first (its side's first
        stand's row for the pool, the serving stand's row for another destination), the near
        slots first."""
        first = (self.stands_of(robot)[0].row if self.destination(name) == POOL
                 else self.serving(self.destination(name)).row)
        return sorted(range(len(self.plate_slots)),
                      key=lambda k: (self.slot_row(k) != first, k))

    def free_slots(self, name: str, taken: Dict[int, str],
                   to_come: Optional[Dict[str, int]] = None, robot: str = '') -> List[int]:
        """The free plate slots for a material of class ``name``, in the order they are filled
        (``slot_order``), with the slots ``taken`` (slot: class of what is on it). A pool
        material leaves the last free slots of a set-down destination's row to the materials
        for it not on the plate yet (``to_come`` per class; by default the manifest's less those
        on the plate): with four oranges ahead of the blue, the blue went into the other row,
        and was unloaded there from the platform's stand, the arm going the long way round (a
        trial took 72.4 s against 65 s)."""
        if robot and self.stands and not carries(self, name, robot):
            return []
        free = [k for k in self.slot_order(name, robot) if k not in taken]
        if self.destination(name) != POOL or not self.stands:
            return free
        kept: Set[Any] = set()
        side = self.side_of(robot)
        for row in {st.row for st in self.stands if st.serves - {POOL} and st.side == side}:
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


def pool_sides(layout: CellLayout) -> Tuple[PoolSide, ...]:
    """The pool's sides with stands: the west (the paper's: ``via_out`` and ``via_turn``), then
    ``more_sides``."""
    return (PoolSide(layout.via_out, layout.via_turn, layout.via_turn), *layout.more_sides)


def carries(layout: CellLayout, name: str, robot: str) -> bool:
    """Whether transport ``robot`` may carry class ``name`` (a carried one): into the pool from
    any side, elsewhere only from the side of the stand that serves it."""
    return (layout.destination(name) == POOL
            or layout.serving(layout.destination(name)).side == layout.side_of(robot))


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


def fixed_boxes(obstacles: Sequence[Any]) -> Tuple[Tuple[str, Tuple[float, float, float],
                                                         Tuple[float, float, float], float], ...]:
    """The world's fixed boxes that collide (CellLayout.fixed): name, centre, half sizes, yaw."""
    return tuple((o.name or f'obstacle {k}', tuple(o.position), tuple(v / 2 for v in o.size),
                  o.yaw) for k, o in enumerate(obstacles)
                 if o.shape == 'box' and o.collision and len(o.size) == 3)
