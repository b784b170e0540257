"""The fleet's traffic rules (no ROS): the two places its youBots share, and the one rule for
every drive (docs/writing-a-cell.md, "Several youBots").

- The loading pose and each side of the pool (its unload stands) are each held by one youBot at
  a time, given in the order the youBots asked for them. Each youBot unloads at its own side
  (CellLayout.side_of): with two sides, two youBots unload at once.
- A drive starts only if the base's footprint, all along its path, keeps the cell's clearance
  (and TRACKING_MARGIN_M for the drives' errors) from every other youBot: from where it stands,
  or from the rest of its drive. Nobody waits on a drive already under way, and every drive ends,
  so a drive held back starts once the others have passed.

A fleet of one holds both places all along, and its drives are never held back.
"""
from __future__ import annotations

from typing import Dict, List, Mapping, Optional

import numpy as np

from cell_layout.fleet_routes import keeps_clear
from cell_layout.layout import CellLayout, pool_sides
from controllers.path_follower import PathFollower
from coordinator.pipeline.model import Observation
from coordinator.pipeline.robots import BaseDrive

LOADING, STANDS = 'loading', 'pool'


def stands_place(side: int) -> str:
    """The place that is the stands of the pool's side ``side`` (0: the west)."""
    return STANDS if side == 0 else f'{STANDS} side {side}'
# A base may lag its path's dummy by this much: the rest of its drive is taken from this long
# before now [s].
DRIVE_LAG_S = 1.0


class Traffic:
    def __init__(self, layout: CellLayout, bases: Mapping[str, BaseDrive]) -> None:
        self.layout, self.bases = layout, bases
        first = None if layout.fleet else layout.transport.name
        places = [LOADING, *(stands_place(k) for k in range(len(pool_sides(layout))))]
        self.holder: Dict[str, Optional[str]] = {p: first for p in places}
        self.queue: Dict[str, List[str]] = {p: [] for p in places}

    def ask(self, robot: str, place: str) -> bool:
        """Whether ``robot`` holds ``place`` (given it if it is free and ``robot`` is the first
        to have asked; queued otherwise)."""
        if self.holder[place] == robot:
            return True
        queue = self.queue[place]
        if robot not in queue:
            queue.append(robot)
        if self.holder[place] is None and queue[0] == robot:
            self.holder[place] = queue.pop(0)
            return True
        return False

    def leave(self, robot: str, place: str) -> None:
        """``robot`` no longer holds ``place`` (nor waits for it)."""
        if self.holder[place] == robot and self.layout.fleet:
            self.holder[place] = None
        if robot in self.queue[place]:
            self.queue[place].remove(robot)

    def clear(self, robot: str, follower: PathFollower, obs: Observation) -> bool:
        """Whether ``robot`` may set off on ``follower``'s drive (the rule above)."""
        if not self.layout.fleet:
            return True
        others = [np.vstack([[obs.bases[name].pose], *(
            [base.follower.poses(obs.now - DRIVE_LAG_S)] if base.follower else [])])
            for name, base in self.bases.items() if name != robot]
        return keeps_clear(self.layout, follower.poses(follower.start_time), others)
