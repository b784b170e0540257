"""The geometry of the youBot's unloads (no ROS, no state): the straight lift off its plate and
the points of a grip, where a held material is from the tool, how far the gripper is from a
drop, and whether a motion keeps what is held clear of the plate's other materials. The
coordinator's transport plans with these; tests/unit/test_unload_geometry.py tests each."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import List, Optional, Sequence, Tuple, cast

import numpy as np

from cell_layout.layout import PLATE_TOP_IN_BASE_M, world_to_base
from cell_layout.reach import youbot_tilts
from cell_layout.world_layout import GRASP_STANDOFF_M
from controllers.arrays import Vector
from controllers.bezier import Pose2D
from controllers.youbot_kinematics import YoubotKinematics

# A motion's samples: (absolute time [s], joint positions, velocities, accelerations).
Points = List[Tuple[float, np.ndarray, np.ndarray, np.ndarray]]
# The youBot's fingertips reach 10.4 mm beyond gripper_tcp: it grasps a material's top face with
# the TCP this far above it, so that the fingertips do not push the material away.
YOUBOT_GRASP_STANDOFF_M = GRASP_STANDOFF_M


# The youBot's fingertips reach this far beyond gripper_tcp [m].
YOUBOT_FINGERTIP_M = 0.0104
# Its arm stopped on its way down onto a plate material this far above the grip at most, and
# this near it across, stopped on the material's top: the material stands that much taller
# than loaded (a perturbed cell's edges vary by 4 %: a 56 mm cube stopped the tool 7.6 mm up
# and 8.5 mm across, pushed aside on its top face; within 15 mm the fingertips' centre is still
# over a 50 mm material's top, and far from the next slot's, 60 mm away) [m].
TOUCH_HIGHER_MAX_M = 0.025
TOUCH_ACROSS_MAX_M = 0.015


def touched_edge(q: np.ndarray, contact: np.ndarray) -> Optional[float]:
    """A plate material's edge as the youBot's fingers found it [m], if its arm at ``q``, sent
    down to the grip ``contact`` (joints) and stopped short of it, stopped on the material's
    top: over the grip (less than TOUCH_ACROSS_MAX_M off across) and higher (by 1 mm to
    TOUCH_HIGHER_MAX_M), its fingertips on it; None if it stopped elsewhere."""
    tool, goal = YOUBOT_FK.fk(q)[:3, 3], YOUBOT_FK.fk(contact)[:3, 3]
    higher = float(tool[2] - goal[2])
    if (np.linalg.norm(tool[:2] - goal[:2]) > TOUCH_ACROSS_MAX_M
            or not 0.001 <= higher <= TOUCH_HIGHER_MAX_M):
        return None
    return float(tool[2]) - YOUBOT_FINGERTIP_M - PLATE_TOP_IN_BASE_M


# What the youBot holds passes this far over the tops of the plate's other materials [m].
PLATE_CLEARANCE_M = 0.01
YOUBOT_FK = YoubotKinematics('gripper_tcp')
# An unload whose arm stalled with the gripper further than this from its drop, across, is a
# failure, not a delivery [m] (a shoulder that sagged 0.24 rad under 0.38 kg left it 2 cm off
# across, still over the pool).
DROP_REACH_TOLERANCE_M = 0.05


def clear_of_the_plate(points: Points, others: Sequence[Tuple[float, float, float]],
                       size: float, offset: Vector = (0.0, 0.0), steps: int = 8,
                       off_its_slot: bool = False) -> bool:
    """Whether a youBot motion (samples of time, positions, velocities, accelerations) keeps
    the material of edge ``size`` it holds (gripped by its top face, its centre ``offset``
    from the tool in x and y) ``PLATE_CLEARANCE_M`` over each of the plate's ``others`` (slot
    x, y and edge) wherever it passes over one: along the path the controller follows between
    the samples (cubic in position and velocity). ``off_its_slot``: the motion starts with the
    material standing on its slot (the lift off the plate)."""
    if not others or not points:
        return True
    shift = np.asarray(offset, float)
    # Over a neighbour: nearer than their half edges and 5 mm, centre to centre; or, lifted off
    # its slot beside one nearer than that (a cube 10 mm taller than loaded beside its
    # neighbour), nearer than it starts (less a millimetre): it lifts straight up beside it
    # (judged over it from the start, such a cube had no motion off the plate).
    start = YOUBOT_FK.fk(points[0][1])[:3, 3][:2] + shift
    reaches = []
    for sx, sy, other in others:
        reach = (size + other) / 2 + 0.005
        apart = max(abs(start[0] - sx), abs(start[1] - sy))
        beside = off_its_slot and (size + other) / 2 <= apart < reach
        reaches.append((sx, sy, other, apart - 0.001 if beside else reach))
    for (t0, q0, v0, _), (t1, q1, v1, _) in zip(points, points[1:]):
        h = t1 - t0
        for x in np.linspace(0.0, 1.0, steps, endpoint=False):
            q = ((2 * x**3 - 3 * x**2 + 1) * q0 + (x**3 - 2 * x**2 + x) * h * v0
                 + (-2 * x**3 + 3 * x**2) * q1 + (x**3 - x**2) * h * v1)
            tool = YOUBOT_FK.fk(q)[:3, 3]
            px, py = tool[:2] + shift
            bottom = tool[2] - YOUBOT_GRASP_STANDOFF_M - size
            for sx, sy, other, reach in reaches:
                if (bottom < PLATE_TOP_IN_BASE_M + other + PLATE_CLEARANCE_M
                        and abs(px - sx) < reach and abs(py - sy) < reach):
                    return False
    return True


# The youBot's lift off the plate: heights over the grip [m], the last clear of the neighbours
# (of the paper's 5 cm materials; taller neighbours take it higher, 1 cm at a time).
UNLOAD_LIFT_STEPS_M = (0.01, 0.02, 0.03, 0.04, 0.05, 0.06)
# A second grip of a material presses this much further down [m].
REGRIP_PRESS_M = 0.004


def lift_steps(tallest: float) -> Tuple[float, ...]:
    """Heights over the grip that the straight lift passes through: up until what it holds
    clears the tallest other material on the plate (``tallest``, 0: none) by PLATE_CLEARANCE_M
    (its bottom rises as far as the grip does)."""
    steps = list(UNLOAD_LIFT_STEPS_M)
    while steps[-1] < tallest + PLATE_CLEARANCE_M - 1e-9:
        steps.append(round(steps[-1] + 0.01, 6))
    return tuple(steps)


def grip_points(slot: Vector, size: float, attempts: int, high: bool, tallest: float
                ) -> Tuple[np.ndarray, np.ndarray, List[np.ndarray]]:
    """The tool's points (base_link) for a grip of a material of edge ``size`` on the plate
    slot ``slot`` (x, y): on it (its fingertips round its top face; pressed further down at
    each attempt after the first: ``attempts`` made so far), over it (5 cm with ``high``, else
    3), and up its straight lift."""
    contact = np.array([slot[0], slot[1], PLATE_TOP_IN_BASE_M + size
                        + YOUBOT_GRASP_STANDOFF_M - REGRIP_PRESS_M * attempts])
    hover = contact + np.array([0.0, 0.0, 0.05 if high else 0.03])
    return contact, hover, [contact + np.array([0.0, 0.0, h]) for h in lift_steps(tallest)]


def held_offset(q: np.ndarray, slot: Vector) -> np.ndarray:
    """Where a material gripped over its plate ``slot`` is from the tool at joints ``q`` (x, y
    in base_link): the grip is a few millimetres off the slot's centre, the material with
    it."""
    tool = YOUBOT_FK.fk(q)[:2, 3]
    return cast(np.ndarray, np.asarray(slot, float) - tool)


def short_of(q: np.ndarray, goal: np.ndarray) -> float:
    """How far the gripper at joints ``q`` is from where it is at ``goal``, across [m]."""
    return float(np.linalg.norm(YOUBOT_FK.fk(q)[:2, 3] - YOUBOT_FK.fk(goal)[:2, 3]))


@dataclass
class UnloadPath:
    """The youBot's joint positions for one unload, all at one tool tilt."""
    hover: np.ndarray             # over the material on the plate
    contact: np.ndarray           # the fingers round it
    lift: List[np.ndarray]        # up off the plate, straight, to clear of its neighbours
    over: np.ndarray              # 5 cm above its drop
    drop: np.ndarray              # where it is let go
    place: int = -1               # the destination's slot it is set down on (not the pool)
    pose: Optional[Pose2D] = None  # where the base stands for it
    grip_tilt: int = 0            # the tool's tilt [deg] at the grip...
    drop_tilt: int = 0            # ... and where it lets go: the material level only if equal

    @property
    def level(self) -> bool:
        """Whether what it holds is let go level (as it lay on the plate)."""
        return self.grip_tilt == self.drop_tilt

    @property
    def let_go(self) -> str:
        """How what it holds is let go: 'level', or 'tilted N deg'."""
        return 'level' if self.level else f'tilted {abs(self.drop_tilt - self.grip_tilt)} deg'


# A youBot unload whose drop is reached at another tool tilt than its grip rises this much more
# before the wrist turns [m].
TILT_CHANGE_RISE_M = 0.06
# ... through a point this far apart [m].
RISE_STEP_M = 0.01


def youbot_grip_tilts(grip: Sequence[np.ndarray], load: float) -> Tuple[int, ...]:
    """The tilts [deg] the youBot's arm grips a material at along ``grip`` (its hover, contact
    and lift; base_link), holding ``load`` kg from the contact on (youbot_tilts)."""
    return _grip_tilts(tuple(tuple(np.round(p, 6)) for p in grip), round(load, 6))


@lru_cache(maxsize=256)
def _grip_tilts(grip: Tuple[Tuple[float, ...], ...], load: float) -> Tuple[int, ...]:
    return youbot_tilts([np.array(p) for p in grip], load, held_from=1)


def drop_ways(pose: Pose2D, candidates: Sequence[Tuple[int, np.ndarray]], base_z: float,
              lift_top: float, clear: float, load: float, level: bool,
              leant_first: bool = False
              ) -> List[Tuple[int, np.ndarray, np.ndarray, Tuple[int, ...]]]:
    """For the base at ``pose``, each candidate drop (place, world point) in base_link: its
    place, the drop, the point over it, and (with ``level``) the tilts the arm reaches both at
    holding ``load`` kg (youbot_tilts); with ``leant_first``, the drop that needs the arm
    leant furthest first (a pool's: a grip far back on the plate leans further, and leaves
    the drops reached leaning less to the grips that cannot). Over the drop is
    as high as the lift's top (``lift_top``, base_link) at least, and ``clear`` over it: where
    a joint motion from there straight down to a pool drop (lower than the plate) would swing
    what is held into the plate's next material, one over here keeps it clear."""
    ways = []
    for place, point in candidates:
        drop = world_to_base(pose, point)
        drop[2] -= base_z
        over = drop.copy()
        over[2] = max(drop[2] + 0.05, lift_top, drop[2] + clear)
        ways.append((place, drop, over, youbot_tilts([over, drop], load) if level else ()))
    if level and leant_first:
        ways.sort(key=lambda w: -min(w[3], default=0))
    return ways
