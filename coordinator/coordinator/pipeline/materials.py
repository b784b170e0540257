"""The material book (no ROS): every material the run has seen, and the only writer of each
one's status and place (the slot kept for it on the youBot's plate or at its destination, the
pool drop it went to). The machines ask it what is still to come and where a material may go,
and tell it what became of one; the belt model carries the materials' positions."""
from __future__ import annotations

from typing import Dict, List, Set

import numpy as np

from cell_layout.layout import CellLayout
from coordinator.pipeline.model import Detection, Material, MaterialStatus, Settings, Tally
from coordinator.pipeline.record import EventLog
from trial_record.events import EventKind


class MaterialBook:
    def __init__(self, layout: CellLayout, settings: Settings, log: EventLog) -> None:
        self.layout, self.s, self.log = layout, settings, log
        self.materials: Dict[int, Material] = {}
        self.loaded = 0                                  # put on the youBot's plate
        self._dropped: Dict[str, Set[int]] = {}          # pool drop spots used, per stand

    # --- what became of a material (the book's writers) ----------------------------------------
    def confirm(self, d: Detection, position: np.ndarray, now: float) -> Material:
        """A material the vision confirmed on the belt, at ``position`` now."""
        m = self.materials[d.id] = Material(d.id, d.color, position, now, d.hits, detection=d,
                                            size=self.layout.size_of(d.color))
        return m

    def picking(self, m: Material) -> None:
        """The Zu 12 is on its way to it."""
        m.status = MaterialStatus.PICKING

    def attempt(self, m: Material) -> None:
        """A pick of it has begun (the cup on its way down)."""
        m.attempts += 1

    def left_on_belt(self, m: Material) -> None:
        """Its pick was given up before it began: it waits on the belt again."""
        m.status = MaterialStatus.SEEN

    def give_up(self, now: float, m: Material, kind: EventKind, why: str, robot: str) -> None:
        """Failed (or missed, off the belt's end): the event says why."""
        m.status = MaterialStatus.MISSED if kind is EventKind.MISSED else MaterialStatus.FAILED
        m.failure = why
        self.log.event(now, kind, robot, m, why)

    def free_kept(self, m: Material) -> None:
        """The plate slot and the place kept for it are free again."""
        m.slot = m.place = -1

    def keep_place(self, m: Material, place: int) -> None:
        """Its slot at its destination (or the pool drop it goes to)."""
        m.place = place

    def keep_slot(self, m: Material, slot: int) -> None:
        """Its slot on the youBot's plate."""
        m.slot = slot

    def placed(self, m: Material) -> None:
        """Set down on its destination by the Zu 12."""
        m.status = MaterialStatus.PLACED

    def loaded_on_plate(self, m: Material) -> None:
        """Set down on the youBot's plate by the Zu 12."""
        m.status = MaterialStatus.ON_PLATE
        self.loaded += 1

    def unload_attempt(self, m: Material, place: int) -> None:
        """The youBot's arm is on its way down onto it, for ``place``."""
        m.place = place
        m.unload_attempts += 1

    def delivered(self, m: Material, stand: str) -> None:
        """Set down or dropped at its destination by the youBot, standing at ``stand``."""
        m.status = MaterialStatus.DELIVERED
        if self.layout.region_of(m.color).drop:
            self._dropped.setdefault(stand, set()).add(m.place)

    def left_on_plate(self, m: Material) -> None:
        """Its unload failed: it may still stand on its plate slot, which is not used again."""
        m.left_on_plate = True

    # --- questions ------------------------------------------------------------------------------
    def with_status(self, status: MaterialStatus) -> List[Material]:
        return [m for m in self.materials.values() if m.status == status]

    def dropped(self, stand: str) -> Set[int]:
        """The stand's pool drop spots used so far."""
        return self._dropped.get(stand, set())

    def tally(self) -> Tally:
        """The materials' counts now (the result's, and the published state's)."""
        return Tally.of(list(self.materials.values()), self.layout.total)

    def all_done(self) -> bool:
        """Every material of the batch at its destination, as far as the coordinator knows."""
        return (all(m.status.done for m in self.materials.values())
                and len(self.materials) == self.layout.total)
