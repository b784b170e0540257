"""The vision-sorting core: segment a frame, locate each material on the belt, track it."""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence

import cv2
import numpy as np

from perception.projection import CameraModel, locate_cube
from perception.segmentation import Blob, ColorClass, confidence, segment
from perception.tracker import Sighting, Track, Tracker

BORDER_PX = 2


@dataclass
class FrameResult:
    blobs: List[Blob]
    observations: List[Sighting]
    tracks: List[Track]          # confirmed tracks seen in this frame


class MaterialVision:
    """Materials are upright cubes resting on the plane z = ``support_z``, of edge ``size``
    unless their class gives its own."""

    def __init__(self, camera: CameraModel, width: int, height: int, support_z: float,
                 size: float, classes: Sequence[ColorClass],
                 min_area_fraction: float = 0.25, yaw: float = 0.0,
                 tracker: Optional[Tracker] = None) -> None:
        self.camera, self.width, self.height = camera, width, height
        self.support_z, self.size, self.yaw = support_z, size, yaw
        self.classes = tuple(classes)
        if not self.classes:
            raise ValueError('no colour classes to look for')
        self.sizes = {c.name: c.size or size for c in self.classes}
        focal = float(camera.k[0, 0])
        self.expected_areas = {}
        for name, edge in self.sizes.items():
            depth = float((camera.position[2] - (support_z + edge)))
            if depth <= 0.0:
                raise ValueError('the camera must be above the materials')
            self.expected_areas[name] = (focal * edge / depth) ** 2
        self.expected_area = min(self.expected_areas.values())
        self.min_area = max(4.0, min_area_fraction * self.expected_area)
        self.tracker = tracker or Tracker()

    def process(self, t: float, rgb: np.ndarray) -> FrameResult:
        if rgb.shape[:2] != (self.height, self.width):
            raise ValueError(f'frame is {rgb.shape[1]}x{rgb.shape[0]}, camera_info says '
                             f'{self.width}x{self.height}')
        blobs = segment(rgb, self.classes, self.min_area)
        observations = []
        for blob in blobs:
            x, y, w, h = blob.bbox
            cut = (x < BORDER_PX or y < BORDER_PX or x + w > self.width - BORDER_PX
                   or y + h > self.height - BORDER_PX)
            if cut:                      # partly out of view: its centroid is not its centre
                continue
            centre, residual = locate_cube(self.camera, blob.u, blob.v, self.support_z,
                                           self.sizes[blob.color], self.yaw)
            if residual > 1.0:
                continue
            observations.append(Sighting(blob.color, centre, blob.u, blob.v,
                                            confidence(blob, self.expected_areas[blob.color])))
        return FrameResult(blobs, observations, self.tracker.update(t, observations))

    def annotate(self, rgb: np.ndarray, result: FrameResult) -> np.ndarray:
        """A copy of the frame with blob outlines, track ids, colours and positions."""
        out = rgb.copy()
        for blob in result.blobs:
            cv2.drawContours(out, [blob.contour], -1, (255, 255, 255), 1)
        for track in result.tracks:
            obs = track.last
            if obs is None:
                continue
            u, v = int(round(obs.u)), int(round(obs.v))
            cv2.drawMarker(out, (u, v), (0, 255, 0), cv2.MARKER_CROSS, 8, 1)
            x, y = track.position[:2]
            cv2.putText(out, f'#{track.id} {track.color} {track.confidence:.2f}', (u + 6, v - 4),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.32, (255, 255, 255), 1, cv2.LINE_AA)
            cv2.putText(out, f'({x:.3f}, {y:.3f})', (u + 6, v + 8), cv2.FONT_HERSHEY_SIMPLEX,
                        0.3, (255, 255, 255), 1, cv2.LINE_AA)
        return np.asarray(out)


def camera_model(k: Sequence[float], position: Sequence[float],
                 rotation: np.ndarray) -> CameraModel:
    return CameraModel(np.asarray(k, float).reshape(3, 3), np.asarray(rotation, float),
                       np.asarray(position, float))

