"""The loader's links against the cell's fixed things (no ROS): its arm's collision model from
its URDF (pinocchio's, with coal: meshes or primitives, whatever the URDF gives), against the
conveyor (its belt, the stand under it and its end stop, as the simulator builds them) and the
world's obstacles (boxes: the stands, the targets, the pool's walls).

The cell plans the tool's way and what it holds clear of things (lift_swing.py,
pick_geometry.py); an arm's links can still strike the conveyor or a stand on the way (a
UFactory xArm 6's upper arm struck the conveyor carrying from the end stop to the plate, its
forearm the target's stand). ``strikes`` tells which link comes within the clearance of what,
along a planned motion's samples. The youBot waiting at the loading pose is among what they keep
clear of (transport_solids), and a place whose way down strikes something is taken on another
branch of the arm's IK (other_branch, clear_branch). A check is 0.03 ms a posture for the Zu 12
(primitives), 0.14 ms for the Panda (meshes), with the youBot's 15 links among the solids.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import coal
import numpy as np
import pinocchio as pin
import pybullet_data

from cell_layout.layout import YOUBOT_CARRY_Q, CellLayout
from cell_layout.reach import loader_solution
from controllers.arm_registry import ArmSpec
from world_description.world_schema import END_STOP_HEIGHT_M, END_STOP_THICKNESS_M

# The simulator's belt is a box this thick under its top, on a stand of 95 % of its length
# and 80 % of its width (sim_bridge/cell.py) [m].
BELT_THICKNESS_M = 0.04
STAND_SHARE = (0.95, 0.8)
# Where a place's way strikes something, the loader's other IK branches tried: from its home,
# then from this many postures drawn within its joint limits (the same every run: drawn by a
# generator of BRANCH_SEED).
BRANCH_TRIES = 24
BRANCH_SEED = 64
# A way through postures is checked at this many samples along each stretch between two.
STRETCH_SAMPLES = 6
# A box: its name, centre (world), half sizes, yaw.
Box = Tuple[str, Tuple[float, float, float], Tuple[float, float, float], float]


def conveyor_boxes(lay: CellLayout) -> List[Box]:
    """The conveyor as the simulator builds it: its belt, the stand under it, its end stop."""
    start = lay.belt_start_x if math.isfinite(lay.belt_start_x) else lay.belt_end_x - 2.0
    length, mid = lay.belt_end_x - start, (lay.belt_end_x + start) / 2
    top, width = lay.belt_top, lay.belt_width
    stand_h = top - BELT_THICKNESS_M
    out: List[Box] = [('conveyor belt', (mid, lay.belt_y, top - BELT_THICKNESS_M / 2),
                       (length / 2, width / 2, BELT_THICKNESS_M / 2), 0.0)]
    if stand_h > 0.01:
        out.append(('conveyor stand', (mid, lay.belt_y, stand_h / 2),
                    (length / 2 * STAND_SHARE[0], width / 2 * STAND_SHARE[1], stand_h / 2),
                    0.0))
    if lay.end_stop:
        out.append(('end stop', (lay.belt_end_x + END_STOP_THICKNESS_M / 2, lay.belt_y,
                                 top + (END_STOP_HEIGHT_M - BELT_THICKNESS_M) / 2),
                    (END_STOP_THICKNESS_M / 2, width / 2,
                     (END_STOP_HEIGHT_M + BELT_THICKNESS_M) / 2), 0.0))
    return out


# A fixed thing as coal checks it: its name, its placement in the world, its shape.
Solid = Tuple[str, pin.SE3, coal.CollisionGeometry]


def box_solids(boxes: Sequence[Box]) -> List[Solid]:
    """Boxes (name, centre, half sizes, yaw) as solids."""
    return [(name, pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, yaw), np.asarray(centre, float)),
             coal.Box(*(2.0 * np.asarray(half, float)))) for name, centre, half, yaw in boxes]


def _collision_model(urdf: str) -> Tuple[pin.Model, pin.GeometryModel]:
    model = pin.buildModelFromUrdf(urdf)
    return model, pin.buildGeomFromUrdf(model, urdf, pin.GeometryType.COLLISION,
                                        package_dirs=[pybullet_data.getDataPath(),
                                                      str(Path(urdf).parent)])


def _link(geometry_name: str) -> str:
    """A URDF link's name from its collision geometry's (pinocchio appends _<k>)."""
    return geometry_name.rsplit('_', 1)[0]


def transport_solids(lay: CellLayout) -> List[Solid]:
    """The first transport robot's links where it is loaded: at the loading pose on its wheels,
    its arm in the carry posture it waits in (an iiwa's forearm struck a youBot's upright arm
    lowering a material onto its plate)."""
    arm = lay.transport.arm
    if arm is None:
        return []
    model, geometry = _collision_model(str(arm.spec.urdf))
    q = pin.neutral(model)
    for name, value in zip(arm.spec.joints, YOUBOT_CARRY_Q):
        if model.existJointName(name):
            q[model.joints[model.getJointId(name)].idx_q] = value
    data, geometry_data = model.createData(), geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, geometry_data, q)
    x, y, yaw = lay.youbot_home
    base = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, yaw), np.array([x, y, lay.youbot_base_z]))
    return [(f'{lay.transport.name}\'s {_link(g.name)}', base * geometry_data.oMg[k],
             g.geometry) for k, g in enumerate(geometry.geometryObjects)]


class LinkClearance:
    """The arm's moving links (their URDF collision geometry) against ``solids`` (world), its
    base where ``spec.base_pose`` stands; ``clearance``: nearer than this counts [m]."""

    def __init__(self, spec: ArmSpec, solids: Sequence[Solid], clearance: float) -> None:
        if spec.base_pose is None:
            raise ValueError('a link check needs the arm\'s base pose in the world')
        full, geometry = _collision_model(str(spec.urdf))
        others = [full.getJointId(n) for n in full.names[1:] if n not in spec.joints]
        if others:
            self.model, self.geometry = pin.buildReducedModel(full, geometry, others,
                                                              pin.neutral(full))
        else:
            self.model, self.geometry = full, geometry
        x, y, z, yaw = spec.base_pose
        base = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, yaw), np.array([x, y, z]))
        links = [k for k, g in enumerate(self.geometry.geometryObjects) if g.parentJoint > 0]
        self.names: Dict[int, str] = {k: self.geometry.geometryObjects[k].name for k in links}
        for name, where, shape in solids:
            k = self.geometry.addGeometryObject(pin.GeometryObject(
                name, 0, 0, base.actInv(where), shape))
            self.names[k] = name
            for link in links:
                self.geometry.addCollisionPair(pin.CollisionPair(link, k))
        self.data, self.geometry_data = self.model.createData(), self.geometry.createData()
        for request in self.geometry_data.collisionRequests:
            request.security_margin = clearance
        self._index = np.array([self.model.getJointId(n) - 1 for n in spec.joints])

    def strikes(self, postures: Sequence[np.ndarray]) -> str:
        """The first link within the clearance of a solid along ``postures`` (the arm's
        joints, in the spec's order), as 'link on solid'; '' if none."""
        q = np.empty(self.model.nq)
        for posture in postures:
            q[self._index] = posture
            if pin.computeCollisions(self.model, self.data, self.geometry,
                                     self.geometry_data, q, True):
                for pair, result in zip(self.geometry.collisionPairs,
                                        self.geometry_data.collisionResults):
                    if result.isCollision():
                        return (f'{_link(self.names[pair.first])} on the '
                                f'{self.names[pair.second]}')
        return ''


_CHECKS: Dict[Tuple[object, ...], Optional[LinkClearance]] = {}


def link_clearance(lay: CellLayout) -> Optional[LinkClearance]:
    """The loader's link check in ``lay`` (remembered per loader and conveyor), None where
    the cell asks none (``link_clearance`` < 0) or the URDF has no collision geometry."""
    if lay.link_clearance < 0.0:
        return None
    spec = lay.loader.model.spec
    boxes = tuple(conveyor_boxes(lay)) + tuple(lay.fixed)
    key = (spec, boxes, lay.link_clearance, lay.transport.arm, lay.youbot_home,
           lay.youbot_base_z)
    if key not in _CHECKS:
        if len(_CHECKS) >= 64:
            _CHECKS.clear()
        check: Optional[LinkClearance] = LinkClearance(
            spec, box_solids(boxes) + transport_solids(lay), lay.link_clearance)
        if check is not None and not check.names:
            check = None
        _CHECKS[key] = check
    return _CHECKS[key]


def way_postures(qs: Sequence[np.ndarray]) -> List[np.ndarray]:
    """Postures along the joints' way through ``qs``, each stretch straight in joint space
    (STRETCH_SAMPLES a stretch)."""
    out = [np.asarray(qs[0], float)]
    for a, b in zip(qs, qs[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        out += [a + (b - a) * s for s in np.linspace(0.0, 1.0, STRETCH_SAMPLES + 1)[1:]]
    return out


def way_strikes(lay: CellLayout, qs: Sequence[np.ndarray]) -> str:
    """What a link strikes along the loader's way through ``qs`` ('' if nothing, or the cell
    asks no check)."""
    links = link_clearance(lay)
    return links.strikes(way_postures(qs)) if links is not None else ''


def _branch_starts(lay: CellLayout, seed: Optional[np.ndarray]) -> List[Optional[np.ndarray]]:
    kin = lay.loader.model.kinematics
    home = lay.loader.model.spec.preferred
    lower, upper = np.asarray(kin.lower, float), np.asarray(kin.upper, float)
    rng = np.random.default_rng(BRANCH_SEED)
    return [seed, None if home is None else np.array(home, float),
            *(rng.uniform(lower, upper) for _ in range(BRANCH_TRIES))]


def clear_branch(lay: CellLayout, points: Sequence[np.ndarray],
                 seed: Optional[np.ndarray] = None) -> Tuple[Optional[List[np.ndarray]], str]:
    """The loader's joints with its tool pointing down at each of ``points`` (world), each
    solved from the one before, on an IK branch whose links keep clear along the way through
    them (way_strikes): the branch ``seed`` leads to first, then its home's, then those of
    BRANCH_TRIES postures within its joint limits. (None, why) where it reaches none of them
    so, why naming what the first branch's links strike ('' where it does not reach)."""
    first = ''
    for start in _branch_starts(lay, seed):
        qs: List[np.ndarray] = []
        for point in points:
            q = loader_solution(lay, point, qs[-1] if qs else start)
            if q is None:
                break
            qs.append(q)
        if len(qs) < len(points):
            continue
        hit = way_strikes(lay, qs)
        if not hit:
            return qs, ''
        first = first or hit
    return None, first


def other_branch(lay: CellLayout, points: Sequence[np.ndarray],
                 qs: Optional[Sequence[np.ndarray]]) -> Optional[np.ndarray]:
    """Where the loader's way through ``qs`` (its joints at ``points``, and maybe at more
    after them) strikes something: its joints at the first point on a branch whose way keeps
    clear (clear_branch); None where the way is clear, or no branch is, or ``qs`` is None."""
    if qs is None or not way_strikes(lay, qs[:len(points)]):
        return None
    clear, _ = clear_branch(lay, points, np.asarray(qs[0], float))
    return None if clear is None else clear[0]
