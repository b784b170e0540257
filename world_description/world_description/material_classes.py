"""Material classes: what a cell sorts, how the camera tells the classes apart, and where each
goes (docs/writing-a-cell.md).

A class has a colour (the simulator paints its cubes with it, the vision node looks for its
hue), a size and a mass, how many of it one run brings, and its rule: the destination (a named
region of the world: an obstacle's top face) and the route there, ``place`` (the Zu 12 sets it
down there itself) or ``carry`` (the Zu 12 loads it onto the youBot, which carries it there).
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Set, Tuple

RGBA = Tuple[float, float, float, float]

ROUTES = ('place', 'carry')

# The rules of the pipeline paper's cell, for a world that gives only ``counts`` and
# ``colors`` (pipeline_cell.yaml as it was written first): purple onto the ground target by the
# Zu 12; orange into the pool and blue onto the pool's platform, by the youBot.
PAPER_RULES: Dict[str, Tuple[str, str]] = {
    'purple': ('ground_target', 'place'),
    'orange': ('pool_floor', 'carry'),
    'blue': ('pool_platform', 'carry'),
}

# The camera's classes are hue ranges (OpenCV hue, 0..180 for 0..360 degrees). A class's range
# reaches this far either side of its colour's hue, and never past the middle between its hue
# and the next class's. Two hues nearer than MIN_HUE_APART cannot be told apart: rendering,
# lighting and noise move a face's hue by a few units (the paper's three classes measured within
# 3 of their colours' hues).
HUE_HALF_WIDTH = 14
MIN_HUE_APART = 10
# The least saturation and value of a class's colour (0..1): the segmentation counts pixels from
# 110/255 saturation and 50/255 value as coloured (the grey belt, the floor and shadows are not),
# and a face in shadow is darker than its colour.
MIN_SATURATION = 0.55
MIN_VALUE = 0.4


@dataclass(frozen=True)
class MaterialClass:
    name: str
    color: RGBA
    count: int
    destination: str                 # a region of the world: the name of an obstacle
    route: str                       # 'place' (by the Zu 12) or 'carry' (by the youBot)
    size: float                      # cube edge [m]
    mass: float                      # [kg]
    hue: Tuple[int, int]             # the camera's OpenCV hue range (lo > hi: wraps past 180)


def hue_of(color: Sequence[float]) -> float:
    """The colour's hue on OpenCV's scale (0..180)."""
    h, _, _ = colorsys.rgb_to_hsv(*color[:3])
    return 180.0 * h


def hue_distance(a: float, b: float) -> float:
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def color_problem(name: str, color: Sequence[float]) -> Optional[str]:
    """Why the camera could not tell a material of ``color`` from the belt, or None."""
    _, s, v = colorsys.rgb_to_hsv(*color[:3])
    if s < MIN_SATURATION:
        return (f'colour {list(color)} of {name} has saturation {s:.2f}, under '
                f'{MIN_SATURATION}: the camera cannot tell it from the grey belt')
    if v < MIN_VALUE:
        return (f'colour {list(color)} of {name} has value {v:.2f}, under {MIN_VALUE}: the '
                'camera cannot tell it from a shadow')
    return None


def hue_ranges(colors: Dict[str, Sequence[float]],
               given: Optional[Dict[str, Tuple[int, int]]] = None) -> Dict[str, Tuple[int, int]]:
    """Each class's hue range: ``given`` ones as they are, the others HUE_HALF_WIDTH either side
    of its colour's hue, up to the middle between it and its nearest neighbour. Raises
    ValueError naming two classes the camera cannot tell apart."""
    given = dict(given or {})
    hues = {name: hue_of(c) for name, c in colors.items()}
    names = sorted(hues)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if hue_distance(hues[a], hues[b]) < MIN_HUE_APART:
                raise ValueError(
                    f'{a} and {b} have hues {hues[a]:.0f} and {hues[b]:.0f} (OpenCV, 0..180), '
                    f'under {MIN_HUE_APART} apart: the camera cannot tell them apart')
    ranges = {}
    for name in names:
        if name in given:
            ranges[name] = given[name]
            continue
        h = hues[name]
        near = min((hue_distance(h, hues[o]) for o in names if o != name), default=180.0)
        half = min(float(HUE_HALF_WIDTH), near / 2 - 0.5)
        lo, hi = int(round(h - half)) % 180, int(round(h + half)) % 180
        ranges[name] = (lo, hi)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if _overlap(ranges[a], ranges[b]):
                raise ValueError(f'the hue ranges of {a} {list(ranges[a])} and {b} '
                                 f'{list(ranges[b])} overlap: the camera cannot tell them apart')
    return ranges


def _units(r: Tuple[int, int]) -> Set[int]:
    lo, hi = r
    return set(range(lo, hi + 1)) if lo <= hi else set(range(lo, 181)) | set(range(0, hi + 1))


def _overlap(a: Tuple[int, int], b: Tuple[int, int]) -> bool:
    return bool(_units(a) & _units(b))


def in_range(hue: float, r: Tuple[int, int]) -> bool:
    lo, hi = r
    return lo <= hue <= hi if lo <= hi else (hue >= lo or hue <= hi)
