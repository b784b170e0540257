"""How the loader meets a material on the moving belt and takes it to its place (no ROS): the
pick's motion (over it at a first guess, then met where the belt will have taken it, down, on
it while the cup seals, up), the lift out of the end stop's queue, and the way onto its place.
The loader (loader.py) decides what to pick and when; this plans it, with the arm's IK and the
pure geometry of pick_geometry.py."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, List, Optional, Tuple, Union

import numpy as np

from cell_layout.layout import CellLayout, slot_in_world
from cell_layout.lift_swing import PlaceWay, rise_first
from cell_layout.link_clearance import other_branch
from cell_layout.pick_geometry import (
    EDGE_CLEARANCE_M,
    continuous,
    edge_point,
    lift_line,
    over_the_belt,
    place_points,
    sweeps_into,
)
from controllers.bezier import Pose2D
from controllers.pick_place import PickTiming, follow_pick
from controllers.time_optimal import (
    SAMPLE_PERIOD_S,
    PlanError,
    TooLate,
    Waypoint,
    plan,
    timed_path,
)
from coordinator.pipeline.materials import BeltModel, MaterialBook
from coordinator.pipeline.model import (
    DOWN,
    PICK_LEAD_S,
    PICK_REPLAN_STEP_S,
    PICK_TRIES,
    QUEUE_LIFT_PAUSE_LEAD_S,
    REAIM_LEAD_S,
    REAIM_TOLERANCE_M,
    SETTLE_S,
    Material,
    MaterialStatus,
    Observation,
    Points,
    Settings,
    known,
)
from coordinator.pipeline.robots import Arm, CupPlace
from coordinator.pipeline.room import Room
from trial_record.events import EventKind

# What the loader lifts out of the end stop's queue rises this far over the tallest material
# that can stand next to it before it swings away [m].
QUEUE_SWING_CLEARANCE_M = 0.05
# The way in to a place is checked from where the cup was last this little below the point
# above the place, or higher [m].
ABOVE_TOLERANCE_M = 0.005
# A material met at rest in the end stop's queue is met this long after its belt pause began,
# and that no sooner than it came to rest there [s].
QUEUE_REST_S = 0.1


@dataclass
class Ahead:
    """A pick's motion that goes on to the place: the way there, and the lift point it passes
    on the way."""
    way: PlaceWay
    q_lift: np.ndarray
    lift_end: float               # (about when it passes it)


# A pick that cannot be made before the material leaves the belt.
LEAVE = 'leave'
# A running motion's sample: (time, joint positions, velocities, accelerations).
Moving = Tuple[float, np.ndarray, np.ndarray, np.ndarray]


@dataclass
class PickPlan:
    """A pick as it is planned: its material and timing, where the belt takes the material, and
    the motion to meet it there (joints over it, over the belt's edge, at the lift point)."""
    m: Material
    timing: PickTiming
    track: Callable[[float], np.ndarray]
    start: float                  # when the motion starts
    contact: float                # when the cup is on the material
    q_hover: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q_edge: Optional[np.ndarray] = None
    q_lift: np.ndarray = field(default_factory=lambda: np.zeros(0))
    waypoints: List[Waypoint] = field(default_factory=list)
    points: Points = field(default_factory=list)
    # Re-aimed: the running motion's sample (time, q, v, a) the new one goes on from.
    moving: Optional[Moving] = None
    hover_at: float = math.inf    # when the cup is over the material, about to come down
    # From when the motion may be re-aimed (past a way from a place: its rise and the belt's
    # edge).
    reaim_from: float = math.inf
    reaimed: float = 0.0          # re-aimed: by how far the old plan would have been off [m]

    @property
    def contact_x(self) -> float:
        """Where (along the belt) the plan meets the material."""
        return float(self.track(self.contact)[0])


class PickPlanner:
    """Plans the loader's picks and places; keeps the last pick's lift point."""

    def __init__(self, arm: Arm, book: MaterialBook, belt: BeltModel, cup: CupPlace,
                 layout: CellLayout, settings: Settings,
                 loading: Callable[[], Optional[str]]) -> None:
        """``loading``: the youBot being loaded (None: none waits to be)."""
        self.arm, self.book, self.belt, self.cup = arm, book, belt, cup
        self.loading = loading
        self.room = Room(book, layout, settings)
        self.layout, self.s = layout, settings
        self.lift_point: Optional[np.ndarray] = None     # the last pick's lift point (x, y, z)

    def plate_pose(self, obs: Observation) -> Optional[Pose2D]:
        """Where the youBot being loaded stands (None: none waits to be)."""
        robot = self.loading()
        return None if robot is None else obs.bases[robot].pose

    def approach(self, obs: Observation, pick: 'PickPlan') -> str:
        """The joints over the material at a first guess of the contact time, and over the
        belt's edge on the way there from a place; the contact no sooner than the arm can be
        there. Why not, if it cannot be."""
        m, timing = pick.m, pick.timing
        seed = self.arm.motion.goal if self.arm.has_motion else self.arm.q(obs)
        # The hover point moves with the contact time: a first guess from a rest-to-rest move
        # there, then later by a little until the arm makes it.
        hover = follow_pick(pick.track, pick.contact, m.size, timing)[0][0][1]
        q_hover = self.arm.solve(hover, DOWN, 'world', seed)
        if q_hover is None:
            return 'no IK solution for the pick'
        pick.q_hover = q_hover
        # From a place: back over the belt's edge on the way to the hover point.
        if self.cup.at_release and self.cup.above is not None:
            # (From the plate: round the arc, the cup clear of what rides on the belt.)
            lay, above = self.layout, self.cup.above
            edge = (edge_point(lay, hover, above, m.size + EDGE_CLEARANCE_M, arc=True)
                    if self.cup.onto_plate else edge_point(lay, hover, above, EDGE_CLEARANCE_M))
            pick.q_edge = self.arm.solve(edge, DOWN, 'world',
                                         known(self.cup.above_q, 'the point above the place'))
        # (A first guess: the way to the hover point, at rest there; a plan that cannot make
        # it says by how much.)
        way, wait = self.cup.from_release([Waypoint(q_hover)], pick.q_edge)
        reach = wait + plan(self.arm.q(obs), way, self.arm.limits).end
        pick.contact = max(pick.contact, pick.start + reach + timing.descend)
        return ''

    def not_as_it_queues(self, m: Material, contact: float, timing: PickTiming) -> float:
        """The contact, or later: not while the material comes to rest against another in the
        end stop's queue, between the cup's contact and the lift. Met on the move there, the
        cup carried a 50 mm blue on into the purple the stop held (the camera's estimate 4 mm
        behind), pressed it, and the lift dragged the purple up and off the belt's end. It is
        met once at rest there instead (the belt pauses around that lift; the pause begins
        QUEUE_LIFT_PAUSE_LEAD_S before the contact, after it has come to rest)."""
        belt = self.belt
        rest = belt.comes_to_rest(m)
        # (Resting there by the contact but not yet as the pause begins, it would stop short.)
        begins = contact - QUEUE_LIFT_PAUSE_LEAD_S - QUEUE_REST_S
        if begins < rest <= contact + timing.dwell + timing.lift and belt.crowded(m, rest):
            return rest + QUEUE_LIFT_PAUSE_LEAD_S + QUEUE_REST_S
        return contact

    def lifting(self, pick: 'PickPlan') -> PickTiming:
        """The pick's timing, its lift high enough out of the end stop's queue for what it holds
        to pass QUEUE_SWING_CLEARANCE_M over the tallest material that can be next to it: the
        swing on from the lift point sags and bulges outwards as it begins (a green lifted
        7 cm from behind an orange came down 1.3 cm and 2 cm sideways onto it, and knocked it
        over)."""
        m, timing = pick.m, pick.timing
        if not (self.belt.held_by(m, pick.contact) and self.belt.crowded(m, pick.contact)):
            return timing
        high = self.layout.material_size + QUEUE_SWING_CLEARANCE_M
        return replace(timing, lift_height=max(timing.lift_height, high))

    def meet(self, obs: Observation, pick: 'PickPlan') -> str:
        """The pick's motion (``pick.points``), its contact moved later until the arm makes
        it; why not (or LEAVE: the material leaves the belt first)."""
        m, timing, track = pick.m, pick.timing, pick.track
        refused = ''
        for _ in range(PICK_TRIES):
            if track(pick.contact)[0] < self.s.pick_x - 1e-6:
                pick.contact = self.belt.reaches(m, self.s.pick_x)
            pick.contact = self.not_as_it_queues(m, pick.contact, timing)
            if track(pick.contact + timing.dwell)[0] > (self.layout.belt_end_x - m.size / 2
                                                        + 1e-6):
                return LEAVE                   # off the end (no stop) before the cup is on it
            path, lift = follow_pick(track, pick.contact, m.size, self.lifting(pick),
                                     SAMPLE_PERIOD_S)
            self.lift_point = np.asarray(lift, float)
            qs = self.solve_along(path, lift, pick.q_hover)
            if qs is None:
                return 'no IK solution for the pick path'
            if not continuous([pick.q_hover, qs[0]]):
                pick.q_hover = qs[0]            # (on the other branch, solved from the end)
            times = np.array([t for t, _ in path])
            q_path = np.array(qs[:-1])
            v = np.gradient(q_path, times, axis=0, edge_order=2)
            a = np.gradient(v, times, axis=0, edge_order=2)
            # To the hover point at its time, with the path's velocity; along the path (sent as
            # it is); then up to the lift point, at rest, as fast as the joints allow.
            waypoints = [Waypoint(q_path[0], velocity=v[0], acceleration=a[0], at=times[0])]
            waypoints += [Waypoint(q, velocity=vk, acceleration=ak, at=tk, direct=True)
                          for q, vk, ak, tk in zip(q_path[1:], v[1:], a[1:], times[1:])]
            waypoints += self.lift_way(m, pick, path[-1][1], q_path[-1], times[-1], qs[-1])
            pick.waypoints, pick.q_lift = waypoints, qs[-1]
            try:
                pick.points = self._motion(obs, waypoints, pick)
                pick.hover_at = float(times[0])
                pick.reaim_from = self._past_the_way_in(pick)
                return ''
            except TooLate as too_late:
                pick.contact += max(too_late.by, 0.0) + PICK_LEAD_S / 2
            except PlanError as exc:
                # The joints' path along this stretch of the track is out of the limits (the
                # IK changes branch somewhere on it): meet the material a little further on.
                refused = f'no motion for the pick: {exc}'
                pick.contact += PICK_REPLAN_STEP_S
        return refused or 'the arm cannot meet the material in time'

    def reaim(self, obs: Observation, pick: 'PickPlan', running: Points
              ) -> Union['PickPlan', str, None]:
        """Correction until contact: where the newest sightings and the belt's sensed speed
        put the material at the pick's contact, against where its motion meets it. More than
        REAIM_TOLERANCE_M off, and more than the prediction's own error, the pick planned again
        on from its ``running`` motion's sample a plan latency ahead, to meet the material where
        it will be (up to REAIM_LEAD_S before the cup is over it; not one the end stop holds by
        then, where it rests): the new plan,
        why there is none, or None (nothing to correct). Predicted from a speed measured 2 s
        earlier, a drifting belt had carried materials 33-102 mm from the cup."""
        m = pick.m
        t1 = self.arm.clock.now + self.s.plan_latency
        if (not pick.reaim_from <= t1 < pick.hover_at - REAIM_LEAD_S
                or self.belt.held_by(m, pick.contact)):
            return None
        fresh = self.belt.track(m)
        off = float(fresh(pick.contact)[0]) - pick.contact_x
        after = [p for p in running if p[0] > t1]
        sensed = self.belt.sensed
        known_to = 2.0 * sensed.std * max(0.0, pick.contact - m.last_seen) if math.isfinite(
            sensed.std) else 0.0
        if abs(off) <= max(REAIM_TOLERANCE_M, known_to) or not after:
            return None
        new = PickPlan(m, pick.timing, fresh, after[0][0], pick.contact, q_hover=pick.q_hover,
                       moving=after[0], reaimed=off)
        why = self.meet(obs, new)
        if why:
            pick.reaimed = off                  # (how far off the pick goes on)
            return (f'not re-aimed ({"it leaves the belt first" if why == LEAVE else why}): '
                    f'the pick goes on, {off * 1000:+.0f} mm off')
        return new

    def _motion(self, obs: Observation, waypoints: List[Waypoint], pick: 'PickPlan') -> Points:
        """The pick's motion through ``waypoints``: from where the arm is (after the rise from
        a place, over the belt's edge), or, re-aimed, on from the running motion's sample."""
        if pick.moving is None:
            return self.cup.plan(obs, waypoints, pick.start, pick.q_edge)
        t1, q1, v1, a1 = pick.moving
        return plan(q1, waypoints, self.arm.limits, t1, v0=v1, a0=a1).points()

    @staticmethod
    def _past_the_way_in(pick: 'PickPlan') -> float:
        """When the motion is past its way in from a place (over the belt's edge; its start,
        without one): from then on it may be re-aimed."""
        if pick.moving is not None or pick.q_edge is None:
            return pick.points[0][0] if pick.moving is None else pick.moving[0]
        edge = pick.q_edge
        return min(pick.points, key=lambda p: float(np.max(np.abs(p[1] - edge))))[0]

    def lift_way(self, m: Material, pick: 'PickPlan', on: np.ndarray, q_on: np.ndarray,
                  t_on: float, q_lift: np.ndarray) -> List[Waypoint]:
        """From the dwell (the cup on the material at ``on``, joints ``q_on``, at ``t_on``) up
        to the lift point: as fast as the joints allow; out of the end stop's queue, with
        another material right behind, straight up along the line, timed along it
        (timed_path). The joints' own way from the dwell to the lift point bowed 1.8 cm
        upstream as it began, into the material behind, and lifted the queue with it (the
        ones behind rose up to 4 cm and fell back turned 23 degrees)."""
        timing = pick.timing
        if not (self.belt.held_by(m, pick.contact) and self.belt.crowded(m, pick.contact)):
            return [Waypoint(q_lift, min_time=timing.lift)]
        points = lift_line(on, self.lift_point) if self.lift_point is not None else []
        line = self.arm.solve_path(points, q_on) if points else []
        if line is None or not continuous([q_on, *line, q_lift]):
            return [Waypoint(q_lift, min_time=timing.lift)]
        try:
            return timed_path([q_on, *line, q_lift], self.arm.limits, t_on,
                              min_time=timing.lift)
        except PlanError:
            return [Waypoint(q_lift, min_time=timing.lift)]

    def solve_along(self, path: Any, lift: np.ndarray, seed: np.ndarray
                     ) -> Optional[List[np.ndarray]]:
        """Joints along a pick's path and at its lift point, on one IK branch: near the loader's
        base its elbow can flip between two samples (a path the planner refuses, "joint 3
        acceleration -320"); then the whole path is solved again from its end backwards, on
        the branch the end is on. None if neither is continuous."""
        points = [p for _, p in path] + [lift]
        qs = self.arm.solve_path(points, seed)
        if qs is None or continuous(qs):
            return qs
        back = self.arm.solve_path(points[::-1], qs[-1])
        if back is None or not continuous(back):
            return None
        return back[::-1]

    def onward(self, obs: Observation, pick: 'PickPlan') -> Optional[Ahead]:
        """On to the place in the same motion, through the lift point without stopping there:
        the swing starts during the lift, and the place does not wait for an arrival check at
        the lift point and a plan after it. (A missed grasp stops the arm at the lift point
        instead: see _pick.)"""
        m = pick.m
        place_way = self.place_way(m, self.lift_point, self.plate_pose(obs), pick.q_lift)
        if isinstance(place_way, str):
            return None                 # (the place is planned, or its failure told, later)
        # Lifted out of a queue (at the end stop), it comes to rest at the lift point, clear
        # of its neighbours' tops, before it swings: a swing begun during the lift dragged a
        # purple into the green queued behind it (the arm stalled, the purple fell back onto
        # the belt).
        crowded = self.belt.crowded(m, pick.contact)
        through = (pick.waypoints if pick.waypoints[-1].direct else   # (straight up: _lift_way)
                   pick.waypoints[:-1] + [Waypoint(pick.q_lift, stop=crowded,
                                                   min_time=pick.timing.lift)])
        try:
            whole = self.clear_of_belt(m, pick.q_lift, place_way, lambda way: self._motion(
                obs, through + way, pick), pick.contact + pick.timing.dwell)
        except PlanError:
            return None                 # (the place is planned at the lift point then)
        ahead = Ahead(place_way, pick.q_lift, pick.points[-1][0])
        pick.points = whole
        return ahead

    def clear_of_belt(self, m: Material, q_lift: np.ndarray, way: 'PlaceWay',
                      plan: Callable[[List[Waypoint]], Points], lifted: float = -math.inf
                      ) -> Points:
        """The motion ``plan`` plans through ``way`` from ``m``'s lift point (at ``lifted``),
        clear of what is on the belt and at its end (cell_layout/lift_swing.py)."""
        def planned(up: List[np.ndarray]) -> Points:
            first = [Waypoint(q) for q in up]
            return self.clear_way(plan(first + way.waypoints), way,
                                  lambda waypoints: plan(first + waypoints))
        motion, rises = rise_first(
            self.layout, self.lift_point, m.size, q_lift, planned,
            lambda t: [(f'{o.color} material {o.id} on the belt', [(np.array(
                [*self.belt.track(o)(t)[:2], self.layout.belt_top]), o.size)])
                for o in self.belt.on_belt() if o is not m],
            lambda point, seed: self.arm.solve(point, DOWN, 'world', seed), lifted)
        for why in rises:
            self.arm.log.event(self.arm.clock.now, EventKind.REPLANNED, self.arm.name, m, why)
        return motion

    def place_way(self, m: Material, lift: Optional[np.ndarray], youbot_pose: Optional[Pose2D],
                   seed: np.ndarray) -> Union['PlaceWay', str]:
        """The way from the lift point ``lift`` (x, y, z; None: from above the place) onto
        ``m``'s place, or why there is none: over the belt's edge, to ``place_height`` above
        the place, and straight down until the material is just above it."""
        size, lay = m.size, self.layout
        onto_plate = lay.carried(m.color)
        if not onto_plate:
            region = lay.region_of(m.color)
            free = self.room.free_places(region.name, m)
            if not free:
                return f'{region.name} is full (its {len(region.slots)} slots are taken)'
            self.book.keep_place(m, free[0])
            target = region.slots[m.place]
        else:
            plate = self.loading()
            if plate is None or youbot_pose is None:
                return 'no youBot waits to be loaded'
            free = self.room.plate_slots(m, plate)
            if not free:
                return f'{plate}\'s plate is full'
            self.book.keep_slot(m, free[0], plate)
            target = slot_in_world(youbot_pose, self.layout.plate_slots[m.slot],
                                   self.layout.youbot_base_z, size)
        t = self.s.timing
        # Down onto it from over the materials there already.
        release, above, transfer = place_points(
            target, size, t, self.room.set_down_rise(
                None if onto_plate else lay.destination(m.color), m.plate), lay.belt_top)
        # Over the belt's near edge (rather than up to the carry height over the place and down
        # again), what the cup holds 5 cm over what can ride on the belt: onto the plate round
        # the arc (the way crosses the edge near the plate; before that it lies over the
        # belt), onto the ground target on the straight line, 5 cm over the belt's top.
        edge = (transfer if lift is None else
                edge_point(lay, lift, above, 2 * size + EDGE_CLEARANCE_M, arc=True) if onto_plate
                else edge_point(lay, lift, above, size + EDGE_CLEARANCE_M))
        qs = self.arm.solve_path(points := [transfer, above, release, edge], seed)
        other = other_branch(lay, points[:3], qs)           # (where its links strike something)
        qs = (None if other is None else self.arm.solve_path(points, other)) or qs
        if qs is None:
            return 'no IK solution for the place path'
        q_transfer, q_above, q_release, q_edge = qs
        # Over to a place lower than the belt, the joints' way from the edge down to above it
        # can bulge back out over the belt: then through the transfer point (above the place,
        # clear of the belt) first, and straight down from there.
        over = ([Waypoint(q_transfer, stop=False)]
                if over_the_belt(self.layout, q_edge, q_above, size) else [])
        return PlaceWay([Waypoint(q_edge, stop=False), *over, Waypoint(q_above, stop=False),
                         Waypoint(q_release, hold=SETTLE_S, min_time=t.place_descend)],
                        q_transfer, above, q_above, onto_plate,
                        self._neighbours(m, onto_plate, youbot_pose), size)

    def _neighbours(self, m: Material, onto_plate: bool, youbot_pose: Optional[Pose2D]
                    ) -> List[Tuple[np.ndarray, float]]:
        """The materials at ``m``'s place already (or kept for one): their bottom centres in
        the world and their edges."""
        lay = self.layout
        if onto_plate:
            if youbot_pose is None:
                return []
            taken = self.room.plate_taken(m.plate, but=m)
            return [(slot_in_world(youbot_pose, lay.plate_slots[k], lay.youbot_base_z,
                                   lay.size_of(color)), lay.size_of(color))
                    for k, color in taken.items() if k != m.slot]
        region = lay.region_of(m.color)
        return [(np.asarray(region.slots[x.place], float), x.size)
                for x in self.book.materials.values()
                if x.id != m.id and x.place >= 0 and lay.destination(x.color) == region.name
                and x.status is MaterialStatus.PLACED]

    def clear_way(self, motion: Points, way: PlaceWay, replan: Callable[[List[Waypoint]],
                  Points]) -> Points:
        """``motion`` (planned through ``way``), or, where what the cup holds would come near a
        material at the place on it (sweeps_into), the motion ``replan`` plans through the way
        at rest above the place."""
        if not sweeps_into(self.layout, [p[1] for p in motion], way.neighbours, way.held,
                           float(way.above[2]) - ABOVE_TOLERANCE_M):
            return motion
        return replan(way.stopping_above())

