"""How the youBot takes a material off its plate and over to its drop (no ROS): the joints of an
unload at one tool tilt, from where the base stands or slid along its stand's line for a heavy
material, and the lift off the plate clear of the others; with the pure geometry of
unload_geometry.py. The transport (transport.py) decides what to unload and when."""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from cell_layout.reach import YOUBOT_LOAD_MAX, youbot_hold_need, youbot_tilts
from cell_layout.unload_geometry import (
    RISE_STEP_M,
    TILT_CHANGE_RISE_M,
    YOUBOT_GRASP_STANDOFF_M,
    UnloadPath,
    clear_of_the_plate,
    drop_ways,
    grip_points,
    held_offset,
    youbot_grip_tilts,
)
from controllers.bezier import Pose2D
from controllers.time_optimal import PlanError, Waypoint, timed_path
from coordinator.pipeline.materials import MaterialBook
from coordinator.pipeline.model import Material, Observation, Points, Settings
from coordinator.pipeline.robots import YoubotArm
from coordinator.pipeline.room import Room

# A heavy material's unload slides the base along its stand's line only this far or further
# (nearer, it is unloaded from where the base stands) [m].
SLIDE_MIN_M = 0.03
# The speeds at its top tried for a lift that goes on to the drop, as fractions of its own top
# speed: the one whose whole motion ends soonest within the joints' limits is kept.
UNLOAD_LIFT_END_SPEEDS = (0.0, 0.25, 0.5, 0.75, 1.0)


class UnloadPlanner:
    """Plans the youBot's unloads."""

    def __init__(self, arm: YoubotArm, book: MaterialBook, layout: CellLayout,
                 settings: Settings) -> None:
        self.arm, self.book, self.layout, self.s = arm, book, layout, settings
        self.room = Room(book, layout, settings)

    def stand_for(self, m: Material) -> str:
        """The stand the base unloads ``m`` from."""
        return self.layout.stand_for(m.color, m.slot, m.plate).name

    def unload_path(self, m: Material, pose: Pose2D, seed: np.ndarray,
                     high: bool = False, slide: bool = False, gripped: Optional[int] = None
                     ) -> Optional['UnloadPath']:
        """Joint positions over the material on the plate (5 cm over it with ``high``, else 3), on
        it, up its straight lift clear of its neighbours, above its drop and at its drop, for
        the base standing at ``pose``. The fingers come down from 3 cm over its top face (the
        neighbours' tops are level with it). The material rises 6 cm, over their 5 cm, before it
        swings out, through a point every centimetre at the same tool tilt: between two points
        6 cm apart the joints' straight line swings what is held 2 cm sideways and tilts it 8
        degrees, into a neighbour 1 cm away. With ``slide``, where the arm holds the material
        at none of its drops from ``pose``, the base may stand elsewhere along its stand's
        line: abeam the drop nearest there that it holds it at, or lets it go level at
        (UnloadPath.pose). With ``gripped``, it holds ``m`` already, at that tilt [deg]."""
        size, t = m.size, self.s.timing
        mass = self.layout.rule(m.color).mass
        stand = self.stand_for(m)
        region = self.layout.region_of(m.color)
        # The swing over to a set-down comes in over what is there already (5 cm over the drop
        # is too little for 55 mm materials): it is as high over the drop as that asks.
        clear = 0.0 if region.drop else self.room.set_down_rise(region.name)
        if not region.drop:
            # Its destination's free slots, the first the arm reaches from here.
            up = np.array([0.0, 0.0, size + t.place_gap + YOUBOT_GRASP_STANDOFF_M])
            candidates = [(k, region.slots[k] + up) for k in self.room.free_places(region.name, m)]
        else:
            # The stand's unused drops, in turn (its first may be out of reach from this slot
            # or base pose). Each used once: a cube dropped on another can tumble over the wall.
            drops = self.layout.stand(stand).drops
            used = self.book.dropped(stand)
            candidates = [(k, d) for k, d in enumerate(drops) if k not in used]
        # First a way whose every pose the arm holds with the material at rest (its load
        # within youbot_holds); only if there is none, the first it reaches (a heavy material
        # held out over a far drop sags the arm, but is still delivered). Each first let go
        # level, from where the base stands or slid along its stand's line, and only then
        # tilted (a pool drop).
        loads = (mass, 0.0) if mass > 0.0 else (0.0,)
        for load in loads:
            for level in (True, False) if region.drop else (True,):
                path = self.unload_way(m, pose, seed, high, load, candidates, clear, level,
                                       gripped)
                if path is None and slide and load == loads[0]:
                    path = self.slid_way(m, pose, seed, high, load, candidates, clear, level,
                                         gripped)
                if path is not None:
                    return path
        return None

    def slid_way(self, m: Material, pose: Pose2D, seed: np.ndarray, high: bool, load: float,
                 candidates: Sequence[Tuple[int, np.ndarray]], clear: float, level: bool,
                 gripped: Optional[int]) -> Optional['UnloadPath']:
        """unload_way from the base slid along its stand's line abeam of a candidate (at least
        SLIDE_MIN_M from ``pose``), in their order (not the shortest slide: an orange so taken
        far in landed on another): what the arm does not hold out, or let go level, from
        ``pose`` it may from there."""
        stand = self.layout.stand(self.stand_for(m))
        for place, point in candidates:
            at = stand.abeam(point)
            if math.hypot(at[0] - pose[0], at[1] - pose[1]) < SLIDE_MIN_M:
                continue
            path = self.unload_way(m, at, seed, high, load, [(place, point)], clear, level,
                                   gripped)
            if path is not None:
                return path
        return None

    def unload_way(self, m: Material, pose: Pose2D, seed: np.ndarray, high: bool,
                   load: float, candidates: Sequence[Tuple[int, np.ndarray]], clear: float,
                   level: bool = True, gripped: Optional[int] = None) -> Optional['UnloadPath']:
        """unload_path's way to the first of ``candidates`` (place, world point) the arm
        reaches holding ``load`` kg at rest: with ``level`` at the grip's tilt throughout, else
        another at the drop. Tilts are tried first with the arm's own kinematics (youbot_tilts,
        0.15 ms a point): a candidate none reaches costs no call to the kinematics node."""
        contact, hover, lift = grip_points(self.layout.plate_slots[m.slot], m.size,
                                           m.unload_attempts, high, self.tallest_other(m))
        grip = [hover, contact, *lift]
        grip_tilts = (gripped,) if gripped is not None else youbot_grip_tilts(grip, load)
        ways = drop_ways(pose, candidates, self.layout.youbot_base_z, lift[-1][2], clear, load,
                         level, leant_first=self.layout.region_of(m.color).drop)
        for place, drop, over, tilts in ways:
            if level:
                tilts = tuple(t for t in tilts if t in grip_tilts)
                # (Held from the contact on: the arm must hold it still all the way to its drop.)
                path = (self.arm.solve_tilted([*grip, over, drop], np.array(seed, float), load,
                                              held_from=1, tilts=tilts) if tilts else None)
                if path is not None:
                    return UnloadPath(path[0], path[1], path[2:-2], path[-2], path[-1], place,
                                      pose, self.arm.tilt_deg, self.arm.tilt_deg)
                continue
            way = self.tilted_way(grip, over, drop, seed, load, grip_tilts)
            if way is not None:
                (q, a, b) = way
                return UnloadPath(q[0], q[1], q[2:-2], q[-2], q[-1], place, pose, a, b)
        return None

    def tilted_way(self, grip: List[np.ndarray], over: np.ndarray, drop: np.ndarray,
                   seed: np.ndarray, load: float, grip_tilts: Sequence[int]
                   ) -> Optional[Tuple[List[np.ndarray], int, int]]:
        """A way to a pool drop leaning another way than the grip (what it holds is let go
        tilted): TILT_CHANGE_RISE_M higher first, straight up at the grip's tilt, a point every
        RISE_STEP_M, so that it clears the plate's others as the wrist turns (in one joint step
        it swung 2 cm sideways, into the next material). The joints, grip's and drop's tilt."""
        rise = np.array(grip[-1], float) + np.array([0.0, 0.0, TILT_CHANGE_RISE_M])
        above = np.array(over, float)
        above[2] = max(over[2], rise[2])
        drop_tilts = youbot_tilts([above, drop], load)
        path = (self.arm.solve_tilted([*grip, rise], np.array(seed, float), load, held_from=1,
                                      tilts=grip_tilts) if grip_tilts and drop_tilts else None)
        if path is None:
            return None
        tilt = self.arm.tilt_deg
        steps = [np.array(grip[-1], float) + np.array([0.0, 0.0, h]) for h in
                 np.arange(RISE_STEP_M, TILT_CHANGE_RISE_M - 1e-9, RISE_STEP_M)]
        between = (self.arm.solve_tilted(steps, path[-2], load, tilts=(tilt,)) if steps
                   else [])
        out = (self.arm.solve_tilted([above, drop], path[-1], load, tilts=drop_tilts)
               if between is not None else None)
        if between is None or out is None:
            return None
        return path[:-1] + between + path[-1:] + out, tilt, self.arm.tilt_deg

    def lift(self, obs: Observation, m: Material, carry: UnloadPath,
             then: Sequence[Waypoint] = (), detour: Sequence[Waypoint] = ()) -> Points:
        """The motion from the grip: the straight lift off the plate, timed along the line (a
        joint motion between its ends would swing the material into its neighbours), at rest
        at its top, or going on from there through ``then`` (or ``detour`` where ``then``
        would not keep ``m`` clear of the plate's other materials): at the speed, of those
        tried, that ends soonest and keeps the joints within their limits."""
        return self.lift_from(self.arm.q(obs), m, carry, then, detour)

    def lift_from(self, q: np.ndarray, m: Material, carry: UnloadPath,
                  then: Sequence[Waypoint] = (), detour: Sequence[Waypoint] = ()) -> Points:
        """``lift``, the arm at ``q`` (gripping ``m`` on its slot)."""
        limits = self.arm.limits
        others = self.others(m)
        offset = held_offset(q, self.layout.plate_slots[m.slot])
        for way in ((then, detour) if detour else (then,)):
            best = None
            for speed in (UNLOAD_LIFT_END_SPEEDS if way else (0.0,)):
                lift = timed_path([q, *carry.lift], limits,
                                  self.arm.clock.now + self.s.plan_latency, end_speed=speed,
                                  min_time=self.s.timing.lift)
                try:
                    points = self.arm.plan(q, [*lift, *way])
                except PlanError:
                    continue
                within = all(np.all(np.abs(v) <= limits.velocity) for _, _, v, _ in points)
                if (within and (best is None or points[-1][0] < best[-1][0])
                        and clear_of_the_plate(points, others, m.size, offset,
                                               off_its_slot=True)):
                    best = points
            if best is not None:
                return best
        raise PlanError('no motion off the plate within the joint limits and clear of the '
                        'other materials')

    def tallest_other(self, m: Material) -> float:
        """The tallest material on the plate but ``m`` (0: none)."""
        return max((o.size for o in self.book.materials.values()
                    if o.on_plate_of(m.plate) and o is not m), default=0.0)

    def held_offset(self, obs: Observation, m: Material) -> np.ndarray:
        """Where ``m``, gripped over its plate slot, is from the tool (held_offset)."""
        return held_offset(self.arm.q(obs), self.layout.plate_slots[m.slot])

    def others(self, m: Material) -> List[Tuple[float, float, float]]:
        """The materials on the plate but ``m``: their slots (x, y) and sizes."""
        return [(*self.layout.plate_slots[o.slot], o.size)
                for o in self.book.materials.values()
                if o.on_plate_of(m.plate) and o.slot >= 0 and o.id != m.id]

    def held_beyond(self, obs: Observation, m: Material) -> str:
        """Where the arm, as it stands, holds ``m`` beyond what it may (YOUBOT_LOAD_MAX of a
        joint's effort, at rest): which joint, and the torque it takes ('' where it does not):
        an arm that cannot hold its load sags, and says why."""
        mass = self.layout.rule(m.color).mass
        joint, torque, effort = youbot_hold_need(self.arm.q(obs), mass)
        if torque <= YOUBOT_LOAD_MAX * effort:
            return ''
        return (f'; holding {mass:g} kg there, {joint} needs {torque:.2f} N m at rest '
                f'(its motor: {effort:g} N m)')

