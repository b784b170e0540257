"""A fixed camera's static scene, drawn once.

PyBullet's CPU renderer costs about 0.3 us for every pixel a surface covers, whatever the
triangles, and most of what the belt camera sees never moves: the floor, the belt, its stand, the
end stop, the targets. A fixed camera's frame is therefore drawn with the static bodies hidden
(the renderer skips a shape whose alpha is 0), over an image of the static bodies alone, drawn
once in a client of their own with the same camera. Each pixel takes the nearer of the two by
the depth buffer, which is the renderer's own test between the two draws: without shadows, a
surface's colour depends on nothing but itself and the light, so the result is the frame drawn
whole, bit for bit (tested over frames with materials and an arm in view).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from sim_bridge.client import Client

# Static visual shapes this module can draw again in a client of its own.
_SHAPES = (pybullet.GEOM_BOX, pybullet.GEOM_SPHERE, pybullet.GEOM_CYLINDER)

# Draws a client's scene with the camera: (rgba, height x width x 4 uint8; depth, float32).
Renderer = Callable[[BulletClient], Tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class StaticVisual:
    """One visual shape of a static body, as PyBullet holds it."""
    body: int
    link: int
    geometry: int
    dimensions: Tuple[float, float, float]
    frame_position: Tuple[float, float, float]
    frame_orientation: Tuple[float, float, float, float]
    rgba: Tuple[float, float, float, float]
    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]

    def hidden(self) -> Tuple[float, float, float, float]:
        return (*self.rgba[:3], 0.0)


def static_visuals(p: BulletClient, bodies: Sequence[int]) -> Optional[List[StaticVisual]]:
    """The visual shapes of ``bodies`` (static: mass 0, never moved), or None when one of them
    cannot be drawn again alike (a mesh, a link with several shapes, a translucent colour)."""
    out: List[StaticVisual] = []
    for body in bodies:
        shapes = p.getVisualShapeData(body)
        links = [s[1] for s in shapes]
        if len(set(links)) != len(links):
            return None
        pos, orn = p.getBasePositionAndOrientation(body)
        for s in shapes:
            if s[1] != -1 or s[2] not in _SHAPES or s[7][3] != 1.0:
                return None
            out.append(StaticVisual(body, s[1], s[2], tuple(s[3]), tuple(s[5]), tuple(s[6]),
                                    tuple(s[7]), tuple(pos), tuple(orn)))
    return out


def _visual_shape(p: BulletClient, v: StaticVisual) -> int:
    d = v.dimensions
    kwargs = {'rgbaColor': v.rgba, 'visualFramePosition': v.frame_position,
              'visualFrameOrientation': v.frame_orientation}
    if v.geometry == pybullet.GEOM_BOX:
        return int(p.createVisualShape(pybullet.GEOM_BOX, halfExtents=[x / 2 for x in d],
                                       **kwargs))
    if v.geometry == pybullet.GEOM_SPHERE:
        return int(p.createVisualShape(pybullet.GEOM_SPHERE, radius=d[0], **kwargs))
    return int(p.createVisualShape(pybullet.GEOM_CYLINDER, length=d[0], radius=d[1], **kwargs))


class StaticBackdrop:
    """The static scene as one fixed camera sees it: colour and depth of every pixel."""

    def __init__(self, rgba: np.ndarray, depth: np.ndarray) -> None:
        self.words = np.ascontiguousarray(rgba, dtype=np.uint8).view(np.uint32)[..., 0].copy()
        self.depth = np.ascontiguousarray(depth, dtype=np.float32)

    @classmethod
    def measure(cls, visuals: Sequence[StaticVisual], render: Renderer) -> 'StaticBackdrop':
        """Draw ``visuals`` alone, in a client of their own, with ``render``."""
        alone = Client(connection_mode=pybullet.DIRECT)
        try:
            for v in visuals:
                alone.createMultiBody(0.0, -1, _visual_shape(alone, v), basePosition=v.position,
                                      baseOrientation=v.orientation)
            rgba, depth = render(alone)
        finally:
            alone.disconnect()
        return cls(rgba, depth)

    def fill(self, rgba: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """A frame of the moving bodies alone (``rgba``: height x width x 4 uint8, C-contiguous;
        ``depth``: its depth buffer) completed in place with the static scene where that is
        nearer or nothing moving was drawn."""
        np.copyto(rgba.view(np.uint32)[..., 0], self.words, where=self.depth <= depth)
        return rgba
