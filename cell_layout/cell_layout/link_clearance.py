"""The loader's links against the cell's fixed things (no ROS): its arm's collision model from
its URDF (pinocchio's, with coal: meshes or primitives, whatever the URDF gives), against the
conveyor (its belt, the stand under it and its end stop, as the simulator builds them) and the
world's obstacles (boxes: the stands, the targets, the pool's walls).

The cell plans the tool's way and what it holds clear of things (lift_swing.py,
pick_geometry.py); an arm's links can still strike the conveyor or a stand on the way (a
UFactory xArm 6's upper arm struck the conveyor carrying from the end stop to the plate, its
forearm the target's stand). ``strikes`` tells which link comes within the clearance of what,
along a planned motion's samples; a check is 0.02 ms a posture when nothing is near.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import coal
import numpy as np
import pinocchio as pin
import pybullet_data

from cell_layout.layout import CellLayout
from controllers.arm_registry import ArmSpec
from world_description.world_schema import END_STOP_HEIGHT_M, END_STOP_THICKNESS_M

# The simulator's belt is a box this thick under its top, on a stand of 95 % of its length
# and 80 % of its width (sim_bridge/cell.py) [m].
BELT_THICKNESS_M = 0.04
STAND_SHARE = (0.95, 0.8)
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


class LinkClearance:
    """The arm's moving links (their URDF collision geometry) against ``boxes`` (world), its
    base where ``spec.base_pose`` stands; ``clearance``: nearer than this counts [m]."""

    def __init__(self, spec: ArmSpec, boxes: Sequence[Box], clearance: float) -> None:
        if spec.base_pose is None:
            raise ValueError('a link check needs the arm\'s base pose in the world')
        urdf = str(spec.urdf)
        full = pin.buildModelFromUrdf(urdf)
        geometry = pin.buildGeomFromUrdf(full, urdf, pin.GeometryType.COLLISION,
                                         package_dirs=[pybullet_data.getDataPath(),
                                                       str(Path(urdf).parent)])
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
        for name, centre, half, box_yaw in boxes:
            where = base.actInv(pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, box_yaw),
                                        np.asarray(centre, float)))
            k = self.geometry.addGeometryObject(pin.GeometryObject(
                name, 0, 0, where, coal.Box(*(2.0 * np.asarray(half, float)))))
            self.names[k] = name
            for link in links:
                self.geometry.addCollisionPair(pin.CollisionPair(link, k))
        self.data, self.geometry_data = self.model.createData(), self.geometry.createData()
        for request in self.geometry_data.collisionRequests:
            request.security_margin = clearance
        self._index = np.array([self.model.getJointId(n) - 1 for n in spec.joints])

    def strikes(self, postures: Sequence[np.ndarray]) -> str:
        """The first link within the clearance of a box along ``postures`` (the arm's joints,
        in the spec's order), as 'link on box'; '' if none."""
        q = np.empty(self.model.nq)
        for posture in postures:
            q[self._index] = posture
            if pin.computeCollisions(self.model, self.data, self.geometry,
                                     self.geometry_data, q, True):
                for pair, result in zip(self.geometry.collisionPairs,
                                        self.geometry_data.collisionResults):
                    if result.isCollision():
                        return (f'{self.names[pair.first].rsplit("_", 1)[0]} on the '
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
    key = (spec, boxes, lay.link_clearance)
    if key not in _CHECKS:
        if len(_CHECKS) >= 64:
            _CHECKS.clear()
        check: Optional[LinkClearance] = LinkClearance(spec, boxes, lay.link_clearance)
        if check is not None and not check.names:
            check = None
        _CHECKS[key] = check
    return _CHECKS[key]
