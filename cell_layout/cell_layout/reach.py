"""Whether the arms reach a point with their tools as the pipeline uses them (no ROS): the
loader's tool pointing down (whatever the arm: its model is the layout's), the youBot's
fingers down at one tilt in the arm's plane. The layout checks every place with these at
start-up."""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from controllers import youbot_arm
from controllers.arrays import Vector
from controllers.statics import ArmStatics
from controllers.transforms import matrix_to_quaternion, quaternion_to_matrix
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M
from controllers.youbot_kinematics import YoubotKinematics
from robot_description import urdf_path

# The youBot's tool tilts tried for a path, outwards from straight down [deg].
YOUBOT_TILTS_DEG = tuple(range(0, 90, 10))
# The loader's tool straight down: x along world x, z down.
_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


def youbot_tool_quaternion(p: Vector, tilt: float) -> Tuple[float, float, float, float]:
    """Tool orientation (x, y, z, w in base_link) for the youBot's 5-joint arm at ``p``: the
    approach axis down, leaning ``tilt`` away from the arm's base axis in the arm's vertical
    plane (the only orientations a 5-joint arm reaches at an arbitrary point)."""
    phi = math.atan2(p[1] - ARM_BASE_IN_BASE_LINK_M[1], p[0] - ARM_BASE_IN_BASE_LINK_M[0])
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(tilt), math.sin(tilt)
    z = np.array([cp * st, sp * st, -ct])
    y = np.array([-sp, cp, 0.0])
    x = np.array([-cp * ct, -sp * ct, -st])         # y x z
    return matrix_to_quaternion(np.column_stack([x, y, z]))


@lru_cache(maxsize=1)
def _youbot() -> YoubotKinematics:
    return YoubotKinematics('gripper_tcp')


# The largest share of a youBot joint's effort a pose may take to hold the arm and its load at
# rest: the rest is for accelerating it. A 0.38 kg material held at 1.01 of the shoulder's
# 9.5 N m sagged 0.24 rad, and joint 4 at 0.98 of its 2 N m lagged 0.15 rad as it moved;
# the paper's 0.1 kg materials take up to 0.88 of the shoulder at the pool's far drops (the
# arm's own weight, 3.6 kg past the shoulder, is most of it), held without a sag.
YOUBOT_LOAD_MAX = 0.95


@lru_cache(maxsize=1)
def youbot_statics() -> ArmStatics:
    """The youBot arm's gravity model, from its robot description."""
    return ArmStatics(urdf_path('youbot'), youbot_arm.JOINT_NAMES, 'gripper_tcp')


def youbot_holds(qs: Sequence[Vector], payload: float) -> bool:
    """Whether the youBot's arm holds ``payload`` kg at rest at every one of ``qs`` within
    YOUBOT_LOAD_MAX of each joint's effort."""
    statics = youbot_statics()
    return all(statics.load(q, payload) <= YOUBOT_LOAD_MAX for q in qs)


def youbot_hold_need(q: Vector, payload: float) -> Tuple[str, float, float]:
    """The youBot arm's joint that holding ``payload`` kg at rest at ``q`` loads most for its
    effort: (joint, torque [N m], its effort [N m])."""
    statics = youbot_statics()
    torques = np.abs(statics.torques(q, payload))
    k = int(np.argmax(torques / statics.effort))
    return youbot_arm.JOINT_NAMES[k], float(torques[k]), float(statics.effort[k])


def youbot_least_need(points_in_base: Sequence[Vector], payload: float
                      ) -> Optional[Tuple[str, float, float]]:
    """Of the tilts at which the youBot's arm reaches every point (base_link), the one whose
    most loaded joint, holding ``payload`` kg at rest, is loaded least: that joint's
    youbot_hold_need at its worst point; None if no tilt reaches them."""
    best: Optional[Tuple[str, float, float]] = None
    for tilt in YOUBOT_TILTS_DEG:
        qs = _youbot_solutions(points_in_base, tilt)
        if qs is None:
            continue
        need = max((youbot_hold_need(q, payload) for q in qs), key=lambda n: n[1] / n[2])
        if best is None or need[1] / need[2] < best[1] / best[2]:
            best = need
    return best


def _world_to_base(base: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
    x, y, z, yaw = base
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, z])


def loader_reaches(layout: Any, points: Sequence[Vector]) -> bool:
    """Whether the layout's loader (cell_layout.layout.CellLayout) reaches every world point
    with its tool pointing down."""
    return not loader_misses(layout, points)


def loader_misses(layout: Any, points: Sequence[Vector]) -> List[np.ndarray]:
    """The world points the layout's loader does not reach with its tool pointing down."""
    kin = layout.loader.model.kinematics
    rot, origin = _world_to_base(layout.loader_base)
    missed = []
    for p in points:
        target = np.eye(4)
        target[:3, :3] = rot @ _DOWN
        target[:3, 3] = rot @ (np.asarray(p, float) - origin)
        if not kin.ik(target).success:
            missed.append(np.asarray(p, float))
    return missed


def loader_solution(layout: Any, point: Vector, seed: Optional[Vector] = None
                    ) -> Optional[np.ndarray]:
    """The layout's loader's joints with its tool pointing down at a world point, from
    ``seed``; None where it does not reach."""
    kin = layout.loader.model.kinematics
    rot, origin = _world_to_base(layout.loader_base)
    target = np.eye(4)
    target[:3, :3] = rot @ _DOWN
    target[:3, 3] = rot @ (np.asarray(point, float) - origin)
    solution = kin.ik(target, seed)
    return solution.positions if solution.success else None


# Going straight down onto a place, no joint of the loader moves more than this for a
# centimetre of the way [rad] (more: a jump to another branch of its IK on the way).
DESCENT_STEP_M = 0.01
DESCENT_JUMP_RAD = 0.2


def loader_descends(layout: Any, bottom: Vector, rise: float) -> bool:
    """Whether the layout's loader goes straight down from ``rise`` above a world point to
    the point, its tool pointing down, on one branch of its IK (each centimetre's solution
    seeded with the one above)."""
    bottom = np.asarray(bottom, float)
    q = loader_solution(layout, bottom + np.array([0.0, 0.0, rise]))
    steps = max(1, int(math.ceil(rise / DESCENT_STEP_M - 1e-9)))
    for k in range(1, steps + 1):
        if q is None:
            return False
        nxt = loader_solution(layout, bottom + np.array([0.0, 0.0, rise * (1 - k / steps)]), q)
        if nxt is None or float(np.max(np.abs(nxt - q))) > DESCENT_JUMP_RAD:
            return False
        q = nxt
    return q is not None


def tool_points(layout: Any, qs: Sequence[Vector]) -> np.ndarray:
    """Where the loader's tool is in the world at each of the joint positions ``qs``."""
    kin = layout.loader.model.kinematics
    x, y, z, yaw = layout.loader_base
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])         # base -> world
    origin = np.array([x, y, z])
    return np.array([rot @ kin.fk(q)[:3, 3] + origin for q in qs]).reshape(-1, 3)


def tool_positions(layout: Any, q_a: Vector, q_b: Vector, samples: int = 24) -> np.ndarray:
    """Where the loader's tool passes in the world as its joints go in a straight line from
    ``q_a`` to ``q_b`` (``samples`` + 1 points, both ends)."""
    kin = layout.loader.model.kinematics
    x, y, z, yaw = layout.loader_base
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])         # base -> world
    origin = np.array([x, y, z])
    a, b = np.asarray(q_a, float), np.asarray(q_b, float)
    return np.array([rot @ kin.fk(a + f * (b - a))[:3, 3] + origin
                     for f in np.linspace(0.0, 1.0, samples + 1)])


def youbot_reaches(points_in_base: Sequence[Vector], payload: float = 0.0) -> bool:
    """Whether the youBot's arm reaches every point (base_link) at one tool tilt, holding
    ``payload`` kg at rest at each (youbot_holds)."""
    for tilt in YOUBOT_TILTS_DEG:
        qs = _youbot_solutions(points_in_base, tilt)
        if qs is not None and (payload <= 0.0 or youbot_holds(qs, payload)):
            return True
    return False


def youbot_tilts(points_in_base: Sequence[Vector], payload: float = 0.0, held_from: int = 0,
                 tilts: Sequence[int] = YOUBOT_TILTS_DEG) -> Tuple[int, ...]:
    """Those of ``tilts`` [deg] at which the youBot's arm reaches every point (base_link),
    holding ``payload`` kg at rest from point ``held_from`` on (youbot_holds)."""
    found = []
    for tilt in tilts:
        qs = _youbot_solutions(points_in_base, tilt)
        if qs is not None and (payload <= 0.0 or youbot_holds(qs[held_from:], payload)):
            found.append(tilt)
    return tuple(found)


def _youbot_solutions(points_in_base: Sequence[Vector], tilt_deg: float
                      ) -> Optional[List[np.ndarray]]:
    """The youBot arm's joint positions for its tool at each point (base_link) at one tilt,
    or None if it reaches one of them at none."""
    qs = []
    for p in points_in_base:
        target = np.eye(4)
        target[:3, :3] = quaternion_to_matrix(youbot_tool_quaternion(p, math.radians(tilt_deg)))
        target[:3, 3] = p
        solution = _youbot().ik(target)
        if not solution.success or solution.positions is None:
            return None
        qs.append(solution.positions)
    return qs
