"""Minimal x-y path plots as PNG with OpenCV (equal axes, grid, ticks, legend)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Dict, Sequence, Tuple

import cv2
import numpy as np

COLORS = [(31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189), (255, 127, 14)]


def _nice_step(span: float, target_ticks: int = 6) -> float:
    raw = span / target_ticks
    magnitude: float = 10 ** math.floor(math.log10(raw))
    for m in (1, 2, 5, 10):
        if m * magnitude >= raw:
            return m * magnitude
    return 10 * magnitude


def _draw_shapes(img: np.ndarray,
                 shapes: Sequence[Tuple[str, np.ndarray, Sequence[float], bool]],
                 px: Callable[[Sequence[float]], Tuple[int, int]]) -> None:
    """Landmarks: filled in a light tint of their colour, outlined, named at their centre."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    for _, outline, rgba, _ in shapes:
        poly = np.array([px(q) for q in np.asarray(outline, float)], np.int32)
        r, g, b = (int(255 * (0.45 + 0.55 * float(c))) for c in rgba[:3])
        cv2.fillPoly(img, [poly], (b, g, r), cv2.LINE_AA)
        cv2.polylines(img, [poly], True, tuple(int(255 * float(c) * 0.7)
                                               for c in rgba[2::-1]), 1, cv2.LINE_AA)
    for name, outline, _, named in shapes:
        if named and name:
            cx, cy = px(np.asarray(outline, float).mean(axis=0))
            (tw, _), _ = cv2.getTextSize(name, font, 0.4, 1)
            cv2.putText(img, name, (cx - tw // 2, cy + 4), font, 0.4, (60, 60, 60), 1,
                        cv2.LINE_AA)


def line_width(k: int, n: int) -> int:
    """The width [px] of the ``k``-th of ``n`` paths: 6 for the first, 2 for the last."""
    return 2 + round(4 * (n - 1 - k) / (n - 1)) if n > 1 else 2


def plot_paths(paths: Dict[str, np.ndarray], out: Path, title: str,
               size: Tuple[int, int] = (900, 800),
               shapes: Sequence[Tuple[str, np.ndarray, Sequence[float], bool]] = ()) -> None:
    """Draw each (N, 2) array of x, y [m] as a line; start as a circle, end as a square.
    ``shapes``: landmarks under the paths, each (name, (N, 2) closed outline, RGBA fill,
    whether to name it), such as a cell's footprints. The first path is drawn widest and each
    after it narrower, so that one drawn over an identical one leaves it in sight."""
    width, height = size
    left, right, top, bottom = 80, 30, 50, 60
    pts = np.concatenate([p for p in paths.values() if len(p)]
                         + [np.asarray(s[1], float) for s in shapes] or [np.zeros((1, 2))])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = max(float((hi - lo).max()), 0.1) * 1.1
    centre = (lo + hi) / 2
    plot_w, plot_h = width - left - right, height - top - bottom
    scale = min(plot_w, plot_h) / span  # equal axes
    x0 = centre[0] - plot_w / scale / 2
    y0 = centre[1] - plot_h / scale / 2

    def px(p: Sequence[float]) -> Tuple[int, int]:
        return (int(round(left + (p[0] - x0) * scale)),
                int(round(top + plot_h - (p[1] - y0) * scale)))

    img = np.full((height, width, 3), 255, np.uint8)
    step = _nice_step(span)
    font = cv2.FONT_HERSHEY_SIMPLEX
    for i in range(math.floor(x0 / step), math.ceil((x0 + plot_w / scale) / step) + 1):
        x = i * step
        u = px((x, y0))[0]
        if left <= u <= left + plot_w:
            cv2.line(img, (u, top), (u, top + plot_h), (225, 225, 225), 1)
            cv2.putText(img, f'{x:g}', (u - 12, top + plot_h + 20), font, 0.45, (0, 0, 0), 1)
    for j in range(math.floor(y0 / step), math.ceil((y0 + plot_h / scale) / step) + 1):
        y = j * step
        v = px((x0, y))[1]
        if top <= v <= top + plot_h:
            cv2.line(img, (left, v), (left + plot_w, v), (225, 225, 225), 1)
            cv2.putText(img, f'{y:g}', (left - 55, v + 5), font, 0.45, (0, 0, 0), 1)
    _draw_shapes(img, shapes, px)
    cv2.rectangle(img, (left, top), (left + plot_w, top + plot_h), (0, 0, 0), 1)
    cv2.putText(img, 'x [m]', (left + plot_w // 2 - 20, height - 15), font, 0.55, (0, 0, 0), 1)
    cv2.putText(img, 'y [m]', (10, top - 15), font, 0.55, (0, 0, 0), 1)
    cv2.putText(img, title, (left, 30), font, 0.6, (0, 0, 0), 1)
    for k, (name, p) in enumerate(paths.items()):
        color = COLORS[k % len(COLORS)][::-1]  # RGB -> BGR
        width = line_width(k, len(paths))
        if len(p) >= 2:
            cv2.polylines(img, [np.array([px(q) for q in p], np.int32)], False, color, width,
                          cv2.LINE_AA)
        if len(p):
            cv2.circle(img, px(p[0]), 6, color, 2)
            end = px(p[-1])
            cv2.rectangle(img, (end[0] - 5, end[1] - 5), (end[0] + 5, end[1] + 5), color, -1)
        cv2.line(img, (left + 15, top + 20 + 22 * k), (left + 45, top + 20 + 22 * k), color,
                 width)
        cv2.putText(img, f'{name} (o start, # end)', (left + 52, top + 25 + 22 * k), font, 0.5,
                    (0, 0, 0), 1)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), img):
        raise OSError(f'cannot write {out}')
