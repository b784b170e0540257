"""The materials, as the coordinator believes them (no ROS).

- ``MaterialBook``: every material the run has seen, and the only writer of each one's status
  and place (the slot kept for it on the youBot's plate or at its destination, the pool drop it
  went to). The machines ask it what is still to come and where a material may go, and tell it
  what became of one.
- ``BeltModel``: where each material the belt carries is, and will be. What the camera confirmed
  rides on at the belt's speed while the belt runs, and queues at the end stop (or behind what
  the stop holds). The speed is the one the cell senses (``controllers.belt_speed``: the
  slopes of the vision's tracks), not the set point: the belt drifts. Every frame that sees a
  material the belt still carries puts it where the frame shows it, up to the moment the cup
  comes down onto it. The model is carried forward to each observation, and to the moment a
  material is lifted off. It acts on nothing: the run switches the belt and records when
  (``switched``), the machines ask where a material will be (``track``) and when it reaches a
  point (``reaches``).
"""
from __future__ import annotations

import math
from typing import Callable, Dict, List, Optional, Sequence, Set, Tuple, cast

import numpy as np

from cell_layout.layout import CellLayout
from controllers.belt_speed import BeltSpeed, BeltSpeedEstimate
from controllers.belt_travel import BeltTravel, carried
from controllers.conveyor import Item, advance, held
from coordinator.pipeline.clock import Clock
from coordinator.pipeline.model import (
    QUEUE_CLEARANCE_M,
    Detection,
    Material,
    MaterialStatus,
    Settings,
    Tally,
)
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
                                            size=self.layout.size_of(d.color), last_seen=now)
        return m

    def picking(self, m: Material) -> None:
        """The loader is on its way to it."""
        m.status = MaterialStatus.PICKING

    def attempt(self, m: Material) -> None:
        """A pick of it has begun (the cup on its way down)."""
        m.attempts += 1

    def left_on_belt(self, m: Material, at_rest: bool = False) -> None:
        """Its pick was given up before it began (``at_rest``: its attempts on the move
        missed; it is picked once at rest at the end stop): it waits on the belt again."""
        m.status, m.hands_on = MaterialStatus.SEEN, math.inf
        if at_rest:
            m.at_rest_from = m.attempts

    def coming_down(self, m: Material, t: float) -> None:
        """The cup of its pick comes down onto it from ``t`` on (infinity: no longer)."""
        m.hands_on = t

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

    def keep_slot(self, m: Material, slot: int, plate: str) -> None:
        """Its slot on the plate of youBot ``plate``."""
        m.slot, m.plate = slot, plate

    def placed(self, m: Material) -> None:
        """Set down on its destination by the loader."""
        m.status = MaterialStatus.PLACED

    def loaded_on_plate(self, m: Material) -> None:
        """Set down on the youBot's plate by the loader."""
        m.status = MaterialStatus.ON_PLATE
        self.loaded += 1

    def unload_attempt(self, m: Material, place: int) -> None:
        """The youBot's arm is on its way down onto it, for ``place``."""
        m.place = place
        m.unload_attempts += 1

    def sized(self, m: Material, edge: float) -> None:
        """Its edge as the youBot's fingers found it on the plate."""
        m.size = edge

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


# Materials the belt still carries, as the coordinator believes: those a failed pick left there
# too (they ride on, and queue at the stop).
_ON_BELT = (MaterialStatus.SEEN, MaterialStatus.PICKING, MaterialStatus.FAILED)


class BeltModel:
    def __init__(self, layout: CellLayout, materials: Dict[int, Material], clock: Clock,
                 ran_before: bool) -> None:
        self.layout = layout
        self.materials = materials
        self.clock = clock                # the run's time: what ``track`` starts from
        self.running = False
        # (time it took effect, running): the belt's history, for the travel between two times.
        self.log: List[Tuple[float, bool]] = [
            (-math.inf, True) if ran_before else (clock.now, False)]
        self._time = clock.now            # the model's time (``advance``)
        self._t0 = clock.now              # (the origin of ``running_clock``)
        self.estimate = BeltSpeedEstimate(layout.belt_speed)
        self.encoder = BeltTravel(layout.belt_encoder) if layout.belt_encoder > 0.0 else None

    @property
    def sensed(self) -> BeltSpeed:
        """The belt's speed while it runs, as the cell senses it now."""
        return self.estimate.current

    @property
    def speed(self) -> float:
        return self.sensed.speed if self.running else 0.0

    def on_belt(self) -> List[Material]:
        return [m for m in self.materials.values() if m.status in _ON_BELT and not m.picked]

    def _items(self, mats: Sequence[Material]) -> List[Item]:
        # Along the belt as world x (the belt runs along +x; only differences matter).
        return [Item(m.position[0], m.position[1] - self.layout.belt_y, m.size, m.size)
                for m in mats]

    @property
    def stop(self) -> float:
        """The stop's face (world x; infinity without one)."""
        return self.layout.belt_end_x if self.layout.end_stop else math.inf

    def held(self, m: Material) -> bool:
        """Whether the end stop (or what it holds) holds the material now."""
        mats = self.on_belt()
        return m in mats and held(self._items(mats), self.stop)[mats.index(m)]

    def comes_to_rest(self, m: Material) -> float:
        """When the material comes to rest at the end stop or behind what it holds, while the
        belt runs as it does now (now if it is held already; infinity if it never will)."""
        if self.held(m):
            return self.clock.now
        if self.speed <= 0.0 or not math.isfinite(self.stop):
            return math.inf
        track, x = self.track(m), float(m.position[0])
        rest = float(track(self.clock.now + (self.stop - x) / self.speed + 1.0)[0])
        return self.clock.now + max(0.0, rest - x) / self.speed

    def held_by(self, m: Material, t: float) -> bool:
        """Whether the end stop (or what it holds) holds the material at ``t``."""
        return self.comes_to_rest(m) <= t + 1e-9

    def queue_tail(self) -> float:
        """The upstream face of the queue the end stop holds (world x; infinity if none)."""
        mats = self.on_belt()
        flags = held(self._items(mats), self.stop) if mats else []
        return min((m.position[0] - m.size / 2 for m, h in zip(mats, flags) if h),
                   default=math.inf)

    def track(self, m: Material) -> Callable[[float], np.ndarray]:
        """Where the material's centre will be at a time, while the belt runs as it does now:
        carried on, and held once it reaches the stop or what the stop holds."""
        mats = self.on_belt()
        items, k, now, speed = self._items(mats), mats.index(m), self.clock.now, self.speed
        y, z = float(m.position[1]), float(m.position[2])

        def at(t: float) -> np.ndarray:
            return np.array([advance(items, self.stop, speed * max(0.0, t - now))[k], y, z])
        return at

    def reaches(self, m: Material, x: float) -> float:
        """When the material's centre reaches ``x`` (now if it is there already; infinity if it
        never will: the belt is stopped, or the stop holds it upstream of ``x``)."""
        if x > self.layout.belt_end_x - m.size / 2:
            return math.inf                         # beyond the belt's end
        if m.position[0] >= x:
            return self.clock.now
        if self.speed <= 0.0 or self.held(m):
            return math.inf
        t = self.clock.now + (x - m.position[0]) / self.speed
        return t if self.track(m)(t)[0] >= x - 1e-6 else math.inf

    def crowded(self, m: Material, t: float, behind: bool = False) -> bool:
        """Whether another material on the belt will be next to ``m`` at ``t`` (less than
        QUEUE_CLEARANCE_M between their faces along the belt, overlapping across it): a
        material lifted from there drags against it if it moves sideways before it is clear of
        its top. With ``behind``: only one upstream of it (pressed against it by the belt)."""
        mats = self.on_belt()
        if m not in mats:
            return False
        x = self.track(m)(t)[0]
        for o in mats:
            if o is m or (behind and self.track(o)(t)[0] >= x):
                continue
            reach = (m.size + o.size) / 2
            if (abs(self.track(o)(t)[0] - x) < reach + QUEUE_CLEARANCE_M
                    and abs(o.position[1] - m.position[1]) < reach):
                return True
        return False

    def lifted(self, m: Material, now: float) -> None:
        """The cup has lifted the material off the belt (what queued behind it moves on)."""
        self.advance(now)
        m.picked = True

    def advance(self, now: float, readings: Sequence[Tuple[float, float]] = ()) -> None:
        """Carry the model forward to ``now`` (first taking in the encoder's ``readings``,
        (stamp, travel) oldest first, where the conveyor has one: its speed goes into the
        estimate)."""
        if self.encoder is not None and readings:
            for stamp, counted in readings:
                self.encoder.read(stamp, counted)
            speed = self.encoder.speed(self.running_time)
            if speed is not None:
                self.estimate.measured(self.running_clock(self.encoder.newest), *speed)
        travel = (self.encoder.carry(self._time, now, self.sensed.speed, self.running_time)
                  if self.encoder is not None and now > self._time else
                  carried(self.encoder, self._time, now, self.sensed.speed, self.running_time))
        self._time = max(self._time, now)
        if travel <= 0.0:
            return
        mats = self.on_belt()
        for m, x in zip(mats, advance(self._items(mats), self.stop, travel)):
            m.position = np.array([x, m.position[1], m.position[2]])
            m.stamp = now

    def switched(self, now: float, running: bool, effective: float) -> None:
        """The belt was switched at ``now``, taking effect at ``effective``."""
        self.advance(now)
        self.running = running
        self.log.append((max(now, effective), running))

    def running_time(self, t0: float, t1: float) -> float:
        """How long the belt ran between two times [s]."""
        total = 0.0
        log = self.log + [(t1, self.running)]
        for (start, running), (end, _) in zip(log, log[1:]):
            if running:
                total += max(0.0, min(end, t1) - max(start, t0))
        return total

    def sighted(self, m: Optional[Material], d: Detection, now: float) -> None:
        """A frame showed ``m`` again at ``now`` (None: a track not acted on yet, upstream of
        the pick point, where nothing holds what the belt carries). One the belt still carries
        (waiting, or being picked until the cup comes down onto it) is placed where the frame
        puts it (``seen_at``), and its track tells the belt's speed while nothing holds it
        back; any is noted as seen then."""
        if m is None:
            self.estimate.sighted(d.id, self.running_clock(d.stamp), float(d.position[0]))
            return
        on_belt = (m.status in _ON_BELT and not m.picked and d.stamp < m.hands_on)
        if on_belt and not self.held(m):
            self.estimate.sighted(m.id, self.running_clock(d.stamp), float(d.position[0]))
        else:
            self.estimate.forget(m.id)
        if on_belt:
            m.position, m.stamp, m.hits = self.seen_at(d, now), now, d.hits
        m.last_seen = now

    def seen_at(self, d: Detection, now: float) -> np.ndarray:
        """A detection carried to ``now``: in the camera's view the belt carries it freely."""
        travel = carried(self.encoder, d.stamp, now, self.sensed.speed, self.running_time)
        return cast(np.ndarray, np.asarray(d.position, float) + np.array([travel, 0.0, 0.0]))

    def running_clock(self, t: float) -> float:
        """How long the belt had run at ``t`` since the model began (negative before)."""
        return (self.running_time(self._t0, t) if t >= self._t0
                else -self.running_time(t, self._t0))
