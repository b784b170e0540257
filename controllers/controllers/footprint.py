"""Mobile bases' footprints on the floor, and the clearance between them (no ROS).

A footprint is the rectangle a base covers, about its base_link, along its heading and across
it. A base at a pose covers that rectangle turned and moved there; a base driving a path covers
the rectangles at the poses it passes through (its sweep, sampled). The clearance between two
sets of rectangles is the least distance between any two of them (0 where they overlap): the
fleet's traffic rules and start-up checks and the simulator's watch all measure it this way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

Poses = np.ndarray          # (n, 3): x, y, yaw per row


@dataclass(frozen=True)
class Footprint:
    half_length: float      # along the heading, about base_link [m]
    half_width: float       # across it [m]

    @property
    def radius(self) -> float:
        """The circle about base_link that holds the rectangle."""
        return math.hypot(self.half_length, self.half_width)

    def corners(self, pose: Sequence[float]) -> np.ndarray:
        """The rectangle's corners (4 x 2, in order round it) for a base at ``pose``."""
        x, y, yaw = (float(v) for v in pose[:3])
        c, s = math.cos(yaw), math.sin(yaw)
        local = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]) * (
            self.half_length, self.half_width)
        out: np.ndarray = local @ np.array([[c, s], [-s, c]]) + (x, y)
        return out


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons (corners in order) overlap (separating axes)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
        pa, pb = a @ normals.T, b @ normals.T
        if np.any((pa.max(axis=0) < pb.min(axis=0)) | (pb.max(axis=0) < pa.min(axis=0))):
            return False
    return True


def _points_to_edges(points: np.ndarray, poly: np.ndarray) -> float:
    """The least distance from any of ``points`` to any edge of ``poly``."""
    start = poly
    edge = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - start[None, :, :]
    t = np.clip(np.einsum('pek,ek->pe', rel, edge) / np.einsum('ek,ek->e', edge, edge), 0, 1)
    nearest = start[None, :, :] + t[..., None] * edge[None, :, :]
    return float(np.min(np.linalg.norm(points[:, None, :] - nearest, axis=2)))


def polygon_distance(a: np.ndarray, b: np.ndarray) -> float:
    """The least distance between two convex polygons (corners in order); 0 if they overlap."""
    if _overlap(a, b):
        return 0.0
    return min(_points_to_edges(a, b), _points_to_edges(b, a))


def clearance(a: Poses, fa: Footprint, b: Poses, fb: Footprint) -> float:
    """The least distance between a base of footprint ``fa`` at any of the poses ``a`` and one
    of ``fb`` at any of ``b`` (math.inf if either has none). Pairs whose bounding circles are
    farther apart than the least found so far are not measured."""
    a, b = np.atleast_2d(np.asarray(a, float)), np.atleast_2d(np.asarray(b, float))
    if a.size == 0 or b.size == 0:
        return math.inf
    centres = np.linalg.norm(a[:, None, :2] - b[None, :, :2], axis=2)
    bound = centres - fa.radius - fb.radius          # no pair is nearer than this
    best = math.inf
    for i, j in zip(*np.unravel_index(np.argsort(bound, axis=None), bound.shape)):
        if bound[i, j] >= best:
            break
        best = min(best, polygon_distance(fa.corners(a[i]), fb.corners(b[j])))
        if best == 0.0:
            break
    return best
