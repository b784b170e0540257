"""The whole run: the parts (the clock, the record, the material book, the belt model, one arm
object per robot) and the two machines, each given the parts it uses."""
from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Optional

import numpy as np

from cell_layout.layout import CellLayout
from controllers.arrays import Vector
from coordinator.pipeline.clock import Clock
from coordinator.pipeline.loader import Loader
from coordinator.pipeline.materials import BeltModel, MaterialBook
from coordinator.pipeline.model import (
    QUEUE_MARGIN_M,
    LoaderState,
    Material,
    MaterialStatus,
    NodeTimeout,
    Observation,
    Ports,
    Settings,
    Tally,
    TransportState,
)
from coordinator.pipeline.record import EventLog
from coordinator.pipeline.robots import Arm, BaseDrive, YoubotArm, youbot_limits
from coordinator.pipeline.traffic import Traffic
from coordinator.pipeline.transport import Transport
from trial_record.events import Event, EventKind, RunResult


class Pipeline:
    """The whole run: the two machines and the parts they work with. Call
    ``tick(observation)`` every control period until ``finished``."""

    def __init__(self, layout: CellLayout, ports: Ports, settings: Optional[Settings] = None,
                 start_time: float = 0.0, belt_ran_before: bool = False) -> None:
        """``belt_ran_before``: the belt was already running at the layout's speed when the
        run started (a real-time simulator started with its belt on, the coordinator later):
        what a frame showed before the start has ridden on since."""
        self.layout, self.ports, self.s = layout, ports, settings or Settings()
        if layout.pick_from > self.s.pick_x:
            # (The loader reaches the belt only from here on: it picks there.)
            self.s = replace(self.s, pick_x=layout.pick_from)
        self.start_time = start_time
        self.result: Optional[RunResult] = None
        self.clock = Clock(start_time)
        self.log = EventLog(ports, list(layout.robots))
        self.book = MaterialBook(layout, self.s, self.log)
        self.belt = BeltModel(layout, self.book.materials, self.clock, belt_ran_before)
        self.belt_stops = 0               # the belt stopped while loading (its queue full)
        self.loader_arm = Arm(layout.loader.name,
                              layout.loader.model.limits(self.s.loader_scaling), ports, self.s,
                              self.clock, self.log)
        self.loader = Loader(self.loader_arm, self.book, self.belt, self.log, layout, self.s,
                             ports, loading=lambda: next((t.robot for t in self.transports
                                                          if t.loading), None))
        # One youBot object per transport robot, each with its arm and its base; the traffic
        # rules between them.
        bases = {r.name: BaseDrive(r.name, ports, self.log, self.s) for r in layout.transports}
        self.traffic = Traffic(layout, bases)
        self.transports = [Transport(
            YoubotArm(r.name, youbot_limits(self.s), ports, self.s, self.clock, self.log),
            self.book, self.log, layout, self.s, ports,
            loader_done=lambda: self.loader.state is LoaderState.DONE,
            loader_clear=self.loader.clear_of_the_plate, base=bases[r.name],
            traffic=self.traffic) for r in layout.transports]
        self.transport = self.transports[0]
        self.youbot = self.transport.arm

    # --- what the node and the tests read -------------------------------------------------------
    @property
    def now(self) -> float:
        return self.clock.now

    @property
    def materials(self) -> Dict[int, Material]:
        """Every material seen, by id (the book's)."""
        return self.book.materials

    @property
    def events(self) -> List[Event]:
        return self.log.events

    # --- the loop -----------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        return self.result is not None

    def tick(self, obs: Observation) -> None:
        if self.finished:
            return
        self.clock.now = obs.now
        try:
            if self.loader.state is LoaderState.START:
                self.loader_arm.started(obs)
                for t in self.transports:
                    t.arm.started(obs)
                self.loader.start(obs)
            self._see(obs)
            self.loader.tick(obs)
            self._belt(obs.now, self._belt_wanted(obs.now))
            for t in self.transports:
                t.tick(obs)
            if obs.now - self.start_time > self.s.run_timeout:
                self._finish(obs.now, 'timeout', f'the run took over {self.s.run_timeout} s')
            elif (self.loader.state is LoaderState.DONE
                  and all(t.state is TransportState.DONE for t in self.transports)):
                self._finish(obs.now, 'completed' if self.book.all_done() else 'incomplete', '')
        except NodeTimeout as exc:
            self._finish(obs.now, 'node_timeout', str(exc))

    def tally(self) -> Tally:
        """The materials' counts now (the result's, and the published state's)."""
        return self.book.tally()

    def abort(self, now: float, status: str, message: str) -> None:
        """End the run from outside (the node lost its simulator, or was interrupted)."""
        if not self.finished:
            self._finish(now, status, message)

    # --- the belt -----------------------------------------------------------------------------
    def _belt(self, now: float, running: bool) -> None:
        if running != self.belt.running:
            effective = self.ports.belt(self.layout.belt_speed if running else 0.0)
            self.belt.switched(now, running, effective or now)
            loading = self.loader.state not in (LoaderState.HOME, LoaderState.DONE)
            why = ''
            if not running and loading:
                self.belt_stops += 1            # (stopped for the queue, not at the end)
                why = ('a lift out of the end stop\'s queue' if self.loader.pauses_belt(now)
                       else 'the queue would overflow the belt')
            self.log.event(now, EventKind.BELT_STARTED if running else EventKind.BELT_STOPPED,
                           detail=why)

    def _belt_wanted(self, now: float) -> bool:
        """The belt runs at a uniform speed from the start until loading is over, unless what
        waits for the youBot would overflow it: the end stop's queue reaching back to the pick
        point, or (without a stop) a material the loader cannot take now near the belt's end."""
        if self.loader.state in (LoaderState.HOME, LoaderState.DONE):
            return False
        return not (self.loader.pauses_belt(now) or self._overflow())

    def _overflow(self) -> bool:
        if self.layout.end_stop:
            return self.belt.queue_tail() < self.s.pick_x + QUEUE_MARGIN_M
        end = self.layout.belt_end_x - QUEUE_MARGIN_M
        return any(m.status is MaterialStatus.SEEN and m.position[0] + m.size / 2 > end
                   and self.layout.carried(m.color) and not self.loader.loadable(m)
                   for m in self.belt.on_belt())

    # --- perception ---------------------------------------------------------------------------
    def _see(self, obs: Observation) -> None:
        self.belt.advance(obs.now, obs.belt)    # (with the encoder's counts, if it has one)
        for d in obs.detections:
            m = self.materials.get(d.id)
            if m is None:
                if not self._on_belt_area(d.position) or d.position[0] >= self.s.pick_x:
                    continue
                if d.hits < self.s.confirm_hits:
                    # (Not acted on yet, but upstream of the pick point it rides freely.)
                    self.belt.sighted(None, d, obs.now)
                    continue
                if d.color not in self.layout.rules:
                    continue                # (no class of this cell: the vision's config)
                m = self.book.confirm(d, self.belt.seen_at(d, obs.now), obs.now)
                self.belt.sighted(None, d, obs.now)
                self.log.event(obs.now, EventKind.SEEN, 'vision', m,
                               f'at {np.round(m.position, 3).tolist()}')
            else:
                self.belt.sighted(m, d, obs.now)
        # The belt's speed, as these frames (and its encoder, if it has one) tell it.
        self.belt.estimate.update(self.belt.running_clock(obs.now))
        # Without an end stop, a material still on the belt past its end was not picked.
        for m in self.materials.values():
            if (m.status == MaterialStatus.SEEN and not self.layout.end_stop
                    and m.position[0] > self.layout.belt_end_x):
                self.book.give_up(obs.now, m, EventKind.MISSED, 'went off the belt end unpicked',
                                  self.loader_arm.name)

    def _on_belt_area(self, position: Vector) -> bool:
        """Whether a detection lies on the belt. The camera also sees beside it, and downstream
        of the pick point, where the loader lifts materials and carries them to their places: a
        material in the cup is not a new one. A new material is confirmed where it enters the
        view, upstream of the pick point (``_see``)."""
        return bool(abs(position[1] - self.layout.belt_y) <= self.layout.belt_width / 2)

    # --- the end ------------------------------------------------------------------------------
    def _finish(self, now: float, status: str, message: str) -> None:
        # Leave nothing moving.
        for base in self.layout.transports:
            self.ports.follow(base.name, None)
            self.ports.drive(base.name, 0.0, 0.0, 0.0)
        try:
            self.ports.belt(0.0)
        except NodeTimeout:
            pass
        mats = list(self.materials.values())
        tally = self.tally()
        self.result = RunResult(
            status=status, completion_time=now - self.start_time, total=tally.total,
            identified=tally.identified, picked=tally.picked, delivered=tally.delivered,
            grasp_attempts=self.log.grasp_attempts, grasp_successes=self.log.grasp_successes,
            loader_grasp_attempts=self.log.grasps[self.loader_arm.name][0],
            loader_grasp_successes=self.log.grasps[self.loader_arm.name][1],
            # (The paper's youBot: every transport robot's, together.)
            transport_grasp_attempts=sum(self.log.grasps[t.robot][0] for t in self.transports),
            transport_grasp_successes=sum(self.log.grasps[t.robot][1] for t in self.transports),
            robot_grasps=self.log.by_robot({self.loader_arm.name: 'loader', **{
                t.robot: 'transport' for t in self.transports}}),
            loaded=self.book.loaded, trips=sum(t.trips for t in self.transports),
            belt_stops=self.belt_stops,
            missed=tally.missed, failed=tally.failed, message=message,
            materials=[{'id': m.id, 'color': m.color, 'status': m.status.value,
                        'attempts': m.attempts, 'unload_attempts': m.unload_attempts,
                        'failure': m.failure} for m in mats],
            # A fleet: each youBot's share (one youBot's is the run's own).
            transports={t.robot: {'trips': t.trips, 'carried': t.carried, 'delivered': sum(
                1 for m in mats if m.plate == t.robot and m.status is MaterialStatus.DELIVERED)}
                for t in self.transports} if self.layout.fleet else {})
        self.log.event(now, EventKind.FINISHED,
                       detail=f'{status}{": " + message if message else ""}')
