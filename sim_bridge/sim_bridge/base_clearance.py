"""How near the world's mobile bases came to each other, by the simulation's ground truth (no
ROS): the least distance between two bases' footprints at any physics step since the start or
the last reset, when, and which two. The node latches it on ``~/base_clearance`` (a trial's
result takes it, and a fleet's run is judged by it).

A base's footprint is the rectangle about its base_link that holds its base link and its
wheels (their collision shapes' bounds, measured where it was spawned; a base spawned at a yaw
off the world's axes gets a slightly larger one, which errs on the safe side).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Tuple

import numpy as np

from controllers.footprint import Footprint, clearance
from controllers.transforms import quaternion_to_matrix
from sim_bridge.world import SimRobot

# A new least distance is told at once once it is this much below the last one told; a smaller
# fall waits until this much simulated time has passed [m, s].
TELL_DROP_M = 0.005
TELL_AFTER_S = 0.5


def footprint(robot: SimRobot) -> Footprint:
    """The rectangle about ``robot``'s base_link over its base link and its wheels."""
    c = robot.client
    pos, orn = robot.base_link_world()
    rot = quaternion_to_matrix(orn)
    wheels = robot.drive.joints if robot.drive is not None else ()
    corners = []
    for link in (-1, *wheels):
        lo, hi = c.getAABB(robot.body, link)
        corners += [np.array([x, y, z]) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                    for z in (lo[2], hi[2])]
    local = (np.array(corners) - np.asarray(pos)) @ rot        # (into base_link's axes)
    return Footprint(float(np.max(np.abs(local[:, 0]))), float(np.max(np.abs(local[:, 1]))))


@dataclass
class Closest:
    distance: float = math.inf        # [m]
    time: float = math.nan            # [s] of simulated time
    robots: Tuple[str, str] = ('', '')


class BaseClearance:
    def __init__(self, robots: Mapping[str, SimRobot]) -> None:
        self.robots = {name: r for name, r in robots.items() if r.drive is not None}
        self.footprints: Dict[str, Footprint] = {n: footprint(r) for n, r in self.robots.items()}
        self.closest = Closest()
        self._told = Closest()

    @property
    def watched(self) -> bool:
        """Whether there are two bases to watch."""
        return len(self.robots) > 1

    def reset(self) -> None:
        self.closest, self._told = Closest(), Closest()

    def update(self, time_s: float) -> Optional[Closest]:
        """Measure now; the closest approach if it is to be told now (else None)."""
        if not self.watched:
            return None
        poses = {}
        for name, robot in self.robots.items():
            pos, orn = robot.base_link_world()
            rot = quaternion_to_matrix(orn)
            poses[name] = np.array([[pos[0], pos[1], math.atan2(rot[1, 0], rot[0, 0])]])
        names: List[str] = sorted(poses)
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                d = clearance(poses[a], self.footprints[a], poses[b], self.footprints[b])
                if d < self.closest.distance:
                    self.closest = Closest(d, time_s, (a, b))
        c, told = self.closest, self._told
        if c.distance < told.distance and (
                c.distance <= told.distance - TELL_DROP_M or not math.isfinite(told.distance)
                or time_s - told.time >= TELL_AFTER_S):
            self._told = Closest(c.distance, time_s, c.robots)
            return c
        return None
