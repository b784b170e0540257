"""Colour segmentation of materials in HSV, where hue does not change with lighting."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

import cv2
import numpy as np


@dataclass(frozen=True)
class ColorClass:
    """A colour class: hue ranges (OpenCV hue, 0..180; a range may wrap, lo > hi) and the
    least saturation and value that count as coloured (shadows and the grey belt do not)."""

    name: str
    hue_ranges: Tuple[Tuple[int, int], ...]
    min_saturation: int = 110
    min_value: int = 50
    size: Optional[float] = None      # the class's cube edge [m], if it has its own

    def __post_init__(self) -> None:
        if not self.hue_ranges:
            raise ValueError(f'colour class {self.name}: no hue range')
        for lo, hi in self.hue_ranges:
            if not (0 <= lo <= 180 and 0 <= hi <= 180):
                raise ValueError(f'colour class {self.name}: hue range ({lo}, {hi}) outside '
                                 '0..180')
        for name in ('min_saturation', 'min_value'):
            if not 0 <= getattr(self, name) <= 255:
                raise ValueError(f'colour class {self.name}: {name} outside 0..255')

    def mask(self, hsv: np.ndarray) -> np.ndarray:
        h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
        hue = np.zeros(h.shape, bool)
        for lo, hi in self.hue_ranges:
            hue |= (h >= lo) & (h <= hi) if lo <= hi else (h >= lo) | (h <= hi)
        return (hue & (s >= self.min_saturation) & (v >= self.min_value)).astype(np.uint8)


def classes_of(materials: Any) -> Tuple[ColorClass, ...]:
    """The camera's classes for a world's materials (world_description's MaterialsConfig): each
    class's hue range (from its colour, or as the world gives it) and its size."""
    return tuple(ColorClass(c.name, (tuple(c.hue),), size=c.size) for c in materials.classes)


@dataclass
class Blob:
    color: str
    u: float                  # centroid, pixels (column), sub-pixel
    v: float                  # centroid, pixels (row)
    area: float               # pixels
    bbox: Tuple[int, int, int, int]   # x, y, w, h
    purity: float             # share of the blob's pixels that no other class also claims
    contour: np.ndarray


def segment(rgb: np.ndarray, classes: Sequence[ColorClass],
            min_area: float = 20.0, roi: Optional[Tuple[int, int, int, int]] = None
            ) -> List[Blob]:
    """Blobs of each colour class in an RGB image (uint8, h x w x 3)."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f'expected an h x w x 3 uint8 image, got {rgb.shape} {rgb.dtype}')
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    masks = {c.name: c.mask(hsv) for c in classes}
    # How many classes claim each pixel.
    claimed: np.ndarray = sum(masks.values(), np.zeros(hsv.shape[:2], np.uint8))
    if roi is not None:
        x, y, w, h = roi
        keep = np.zeros(rgb.shape[:2], np.uint8)
        keep[y:y + h, x:x + w] = 1
        masks = {k: m * keep for k, m in masks.items()}
    kernel = np.ones((3, 3), np.uint8)
    blobs = []
    for name, mask in masks.items():
        # Opening removes isolated noisy pixels; closing fills pinholes from noise.
        clean = cv2.morphologyEx(cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel),
                                 cv2.MORPH_CLOSE, kernel)
        contours, _ = cv2.findContours(clean, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        for contour in contours:
            m = cv2.moments(contour)
            area = m['m00']
            if area < min_area:
                continue
            x, y, w, h = cv2.boundingRect(contour)
            region = np.zeros_like(clean)
            cv2.drawContours(region, [contour], -1, 1, thickness=-1)
            inside = region.astype(bool)
            own = mask[inside].sum()
            purity = float((mask[inside] & (claimed[inside] == 1)).sum() / max(own, 1))
            # Pixel centres are at integer coordinates (ROS convention); moments of the filled
            # region give the centroid of its pixel centres.
            ys, xs = np.nonzero(inside)
            blobs.append(Blob(name, float(xs.mean()), float(ys.mean()), float(len(xs)),
                              (x, y, w, h), purity, contour))
    return blobs


def confidence(blob: Blob, expected_area: Optional[float]) -> float:
    """0..1: colour purity times how well the size matches a material's expected image size."""
    if not expected_area:
        return blob.purity
    ratio = max(blob.area / expected_area, 1e-9)
    return float(blob.purity * min(ratio, 1.0 / ratio))
