"""Where the batch's materials may still go (no ROS): what is still to come of each class, the
youBot's plate slots and the destinations' places that are free, and how high a set-down must
swing in over what is there already. Questions only, on the material book (materials.py)."""
from __future__ import annotations

from typing import Dict, List, Optional

from cell_layout.layout import CellLayout
from coordinator.pipeline.materials import MaterialBook
from coordinator.pipeline.model import (
    SET_DOWN_CLEARANCE_M,
    Material,
    MaterialStatus,
    Settings,
)

# Materials not to come any more: on the plate, at their destination, or given up.
_PAST_THE_BELT = (MaterialStatus.ON_PLATE, MaterialStatus.PLACED, MaterialStatus.DELIVERED,
                  MaterialStatus.FAILED, MaterialStatus.MISSED)


class Room:
    def __init__(self, book: MaterialBook, layout: CellLayout, settings: Settings) -> None:
        self.book, self.layout, self.s = book, layout, settings

    def to_come(self, name: str) -> int:
        """Materials of class ``name`` the batch still brings that are not on the plate yet,
        nor placed, delivered or given up (nor being picked for a plate slot kept for it)."""
        gone = sum(1 for m in self.book.materials.values() if m.color == name and (
            m.status in _PAST_THE_BELT
            or (m.status == MaterialStatus.PICKING and m.slot >= 0)))
        return max(0, self.layout.manifest.get(name, 0) - gone)

    def to_come_counts(self) -> Dict[str, int]:
        return {c: self.to_come(c) for c in self.layout.manifest}

    def carried_to_come(self) -> int:
        """Carried materials the youBot has still to take (not on its plate yet)."""
        return sum(self.to_come(c) for c in self.layout.manifest if self.layout.carried(c))

    def plate_taken(self, but: Optional[Material] = None) -> Dict[int, str]:
        """The plate's slots that a material is on, or kept for one being picked, or where one
        the youBot failed to unload may still stand."""
        return {x.slot: x.color for x in self.book.materials.values()
                if x.slot >= 0 and x is not but
                and (x.status in (MaterialStatus.PICKING, MaterialStatus.ON_PLATE)
                     or x.left_on_plate)}

    def plate_slots(self, m: Material) -> List[int]:
        """The plate slots free for ``m`` now, in the order they are filled: for a pool
        material, only in a row whose stand has a drop spot left for it."""
        taken = self.plate_taken(m)
        free = self.layout.free_slots(m.color, taken, self.to_come_counts())
        if not self.layout.region_of(m.color).drop:
            return free
        room = {}
        for st in self.layout.stands:
            bound = sum(1 for k, c in taken.items() if self.layout.slot_row(k) == st.row
                        and self.layout.region_of(c).drop)
            room[st.row] = len(st.drops) - len(self.book.dropped(st.name)) - bound
        return [k for k in free if room.get(self.layout.slot_row(k), 0) > 0]

    def free_places(self, region: str, m: Material) -> List[int]:
        """The slots of a destination (its Region's, in order) that no other material has or
        is kept for: a material never goes down on another."""
        taken = {x.place for x in self.book.materials.values()
                 if x is not m and x.place >= 0
                 and x.status not in (MaterialStatus.FAILED, MaterialStatus.MISSED)
                 and self.layout.destination(x.color) == region}
        slots = self.layout.regions[region].slots
        return [k for k in range(len(slots)) if k not in taken]

    def set_down_rise(self, destination: Optional[str]) -> float:
        """How far over its release point a held material must swing in to a set-down on
        ``destination`` (None: the youBot's plate) to clear the materials there already by
        SET_DOWN_CLEARANCE_M (0: none there)."""
        there = [x.size for x in self.book.materials.values()
                 if (x.on_the_plate if destination is None else
                     x.status in (MaterialStatus.PLACED, MaterialStatus.DELIVERED)
                     and self.layout.destination(x.color) == destination)]
        if not there:
            return 0.0
        return max(there) + SET_DOWN_CLEARANCE_M - self.s.timing.place_gap
