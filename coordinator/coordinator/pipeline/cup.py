"""Where the Zu 12's cup last let go (on the youBot's plate or a destination), and the way up
from there (no ROS): the loader's next motion, whatever it is, first holds still while the
material falls free and rises straight up over the place. The only writer of that state."""
from __future__ import annotations

import math
from typing import List, Optional, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from controllers.time_optimal import Waypoint
from coordinator.pipeline.arm import Arm
from coordinator.pipeline.model import RELEASE_HOLD_S, Observation, Points, Settings, known
from coordinator.pipeline.pick_geometry import over_the_belt


class CupPlace:
    def __init__(self, arm: Arm, layout: CellLayout, settings: Settings) -> None:
        self.arm, self.layout, self.s = arm, layout, settings
        self.then: Optional[np.ndarray] = None      # where the cup rises to from its place
        self.above: Optional[np.ndarray] = None     # above the place (x, y, z), joints
        self.above_q: Optional[np.ndarray] = None
        self.onto_plate = False                     # the last place was on the youBot's plate
        self.clear_point: Optional[np.ndarray] = None   # clear of the place once here (joints)
        # The cup has just let go on the plate or the ground target: the next motion rises
        # first (straight up, after the release hold), whatever it is.
        self.at_release = False
        self.clear_at = -math.inf                   # when the cup is clear of the place

    def adopt(self, then: np.ndarray, above: np.ndarray, above_q: np.ndarray,
              onto_plate: bool) -> None:
        """The place the arm is on its way to: where the cup rises from it to."""
        self.then, self.above, self.above_q, self.onto_plate = then, above, above_q, onto_plate

    def released(self) -> None:
        """The cup has just let go there."""
        self.at_release = True

    def clear(self, now: float) -> bool:
        """Whether the cup is away from where it last let go (not about to rise from it)."""
        return not self.at_release and now >= self.clear_at

    def plan(self, obs: Observation, waypoints: List[Waypoint],
             start: Optional[float] = None, edge: Optional[np.ndarray] = None) -> Points:
        """From a release: the hold, then straight up to above the place and over the belt's
        edge at ``edge`` (joints; towards a pick), or without it up to the carry height."""
        waypoints, wait = self.from_release(waypoints, edge)
        if self.at_release:
            # Clear of the place once straight above it: the cup may be switched on there
            # (what it let go is place_height below it), and the youBot may leave.
            self.clear_point = self.above_q
        return self.arm.plan(self.arm.q(obs), waypoints, wait, start)

    def from_release(self, waypoints: List[Waypoint], edge: Optional[np.ndarray] = None
                     ) -> Tuple[List[Waypoint], float]:
        """``waypoints``, after the rise from a place the cup has just let go at (see plan),
        and how long the motion waits first."""
        if not self.at_release:
            return list(waypoints), 0.0
        rise = self.s.timing.place_descend
        if edge is not None:
            above = known(self.above_q, 'the point above the place')
            # (Up over the place first where the swing from there to the edge would bulge out
            # over the belt, low: see PickPlanner.place_way.)
            then = known(self.then, 'the rise from the place')
            over = ([Waypoint(then, stop=False)] if over_the_belt(self.layout, above, edge, 0.0)
                     and float(np.max(np.abs(then - above))) > 1e-6 else [])
            first = [Waypoint(above, stop=False, min_time=rise), *over,
                     Waypoint(edge, stop=False)]
        else:
            # Straight up over the place first (over what else is there: a swing from the
            # release towards home swept two materials off their slots beside it), then on.
            above = known(self.above_q, 'the point above the place')
            then = known(self.then, 'the rise from the place')
            first = [Waypoint(above, stop=False, min_time=rise)]
            if float(np.max(np.abs(then - above))) > 1e-6:
                first.append(Waypoint(then, stop=not waypoints))
            elif not waypoints:
                first = [Waypoint(above, min_time=rise)]
        return first + list(waypoints), RELEASE_HOLD_S

    def after_send(self) -> None:
        """A motion was sent: one from a release has left it (clear of it when it passes the
        clear point)."""
        if self.at_release:
            self.at_release = False
            self.clear_at = self.arm.arrival_time(known(self.clear_point, 'the clear point'))

