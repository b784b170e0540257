"""Where the batch's materials may still go (no ROS): what is still to come of each class, the
youBot's plate slots and the destinations' places that are free, and how high a set-down must
swing in over what is there already. Questions only, on the material book (materials.py)."""
from __future__ import annotations

from typing import Dict, List, Optional

import numpy as np

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
        """Carried materials the youBots have still to take (not on a plate yet)."""
        return sum(self.to_come(c) for c in self.layout.manifest if self.layout.carried(c))

    def plate_taken(self, plate: str, but: Optional[Material] = None) -> Dict[int, str]:
        """The slots of youBot ``plate``'s plate that a material is on, or kept for one being
        picked, or where one it failed to unload may still stand."""
        return {x.slot: x.color for x in self._on_plates(but) if x.plate == plate}

    def _on_plates(self, but: Optional[Material] = None) -> List[Material]:
        """The materials on any plate (or being picked for one, or left on one)."""
        return [x for x in self.book.materials.values()
                if x.slot >= 0 and x is not but
                and (x.status in (MaterialStatus.PICKING, MaterialStatus.ON_PLATE)
                     or x.left_on_plate)]

    def has_room(self, plate: str, on_plates: Optional[List[Material]] = None,
                 limited: bool = True) -> bool:
        """Whether the trip's load (the cell's ``trip_load``) leaves room on ``plate``
        (``on_plates``: the materials on any plate, if known). The trip's load is a share: it
        holds only while another youBot may carry some of what is still to come (with
        ``limited``); else the plate takes all it can. (With eight materials, the second youBot
        of the example, which does not carry the platform's blue, was done, and the first went
        twice: six, then the blue alone.)"""
        if not (self.layout.trip_load and limited and any(
                self.can_take(r.name, limited=False) for r in self.layout.transports
                if r.name != plate)):
            return True
        on = self._on_plates() if on_plates is None else on_plates
        return sum(1 for x in on if x.plate == plate
                   and not x.left_on_plate) < self.layout.trip_load

    def plate_slots(self, m: Material, plate: str, limited: bool = True) -> List[int]:
        """The slots of youBot ``plate``'s plate free for ``m`` now, in the order they are
        filled (none once it has its trip's load): for a pool material, only in a row whose
        stand has a drop spot left for it (those the materials on every plate will take
        counted)."""
        on_plates = self._on_plates(m)
        if not self.has_room(plate, on_plates, limited):
            return []
        taken = {x.slot: x.color for x in on_plates if x.plate == plate}
        free = self.layout.free_slots(m.color, taken, self.to_come_counts(), plate)
        if not self.layout.region_of(m.color).drop:
            return free
        room = {}
        # (The drop spots of the plate's side of the pool, less those taken and those the
        # materials on the plates of the youBots unloading there will take.)
        side = self.layout.side_of(plate)
        bound = [self.layout.slot_row(x.slot) for x in on_plates
                 if self.layout.region_of(x.color).drop and self.layout.side_of(x.plate) == side]
        for st in self.layout.stands_of(plate):
            room[st.row] = (len(st.drops) - len(self.book.dropped(st.name))
                            - bound.count(st.row))
        return [k for k in free if room.get(self.layout.slot_row(k), 0) > 0]

    def can_take(self, plate: str, limited: bool = True) -> bool:
        """Whether youBot ``plate`` has a place (a plate slot, and a drop spot or slot at its
        destination from its side of the pool) for any carried material still to come: a
        youBot whose side of the pool is full is done. (Not ``limited``: by the trip's load.)"""
        return any(self.plate_slots(Material(-1, c, np.zeros(3), 0.0, 0,
                                             size=self.layout.size_of(c)), plate, limited)
                   for c in self.layout.manifest if self.layout.carried(c) and self.to_come(c))

    def load_complete(self, plate: str, loaded: bool) -> bool:
        """Whether the load of youBot ``plate`` is complete (``loaded``: anything is on it):
        every carried material the batch still brings is on it, or it has no room for the next
        one waiting on the belt (that one goes on the next trip), or it has its trip's load. It
        waits while a carried material on its way to it could still have a place."""
        mats = self.book.materials.values()
        if any(m.status == MaterialStatus.PICKING and self.layout.carried(m.color)
               and m.plate in ('', plate) for m in mats):
            return False
        waiting = [m for m in mats
                   if m.status == MaterialStatus.SEEN and self.layout.carried(m.color)]
        if any(self.plate_slots(m, plate) for m in waiting):
            return False
        if waiting:
            return loaded                   # (full for what waits: off to make room)
        coming = [c for c in self.layout.manifest if self.layout.carried(c) and self.to_come(c)]
        return loaded and (not self.has_room(plate) or not any(
            self.layout.free_slots(c, self.plate_taken(plate), self.to_come_counts(), plate)
            for c in coming))

    def free_places(self, region: str, m: Material) -> List[int]:
        """The slots of a destination (its Region's, in order) that no other material has or
        is kept for: a material never goes down on another."""
        taken = {x.place for x in self.book.materials.values()
                 if x is not m and x.place >= 0
                 and x.status not in (MaterialStatus.FAILED, MaterialStatus.MISSED)
                 and self.layout.destination(x.color) == region}
        slots = self.layout.regions[region].slots
        return [k for k in range(len(slots)) if k not in taken]

    def set_down_rise(self, destination: Optional[str], plate: str = '') -> float:
        """How far over its release point a held material must swing in to a set-down on
        ``destination`` (None: youBot ``plate``'s plate) to clear the materials there already by
        SET_DOWN_CLEARANCE_M (0: none there)."""
        there = [x.size for x in self.book.materials.values()
                 if (x.on_plate_of(plate) if destination is None else
                     x.status in (MaterialStatus.PLACED, MaterialStatus.DELIVERED)
                     and self.layout.destination(x.color) == destination)]
        if not there:
            return 0.0
        return max(there) + SET_DOWN_CLEARANCE_M - self.s.timing.place_gap
