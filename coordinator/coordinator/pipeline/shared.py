"""What the two machines may use of the run they share: everything a machine reads or asks of
the ``Pipeline`` is listed here, and nothing else (mypy holds them to it). A machine does not
see the other machine; what one needs of the other is a question here (``loader_done``,
``zu12_clear_of_the_plate``)."""
from __future__ import annotations

from typing import (
    Dict,
    List,
    Optional,
    Protocol,
    Sequence,
)

import numpy as np

from controllers.arrays import Vector
from controllers.time_optimal import JointLimits, Waypoint
from coordinator.layout import CellLayout
from coordinator.pipeline.belt import BeltModel
from coordinator.pipeline.model import (
    EventKind,
    Material,
    Motion,
    Observation,
    Points,
    Ports,
    Settings,
)


class Shared(Protocol):
    """The run as the machines see it."""

    # --- the cell, the settings, the clock and the ports (read) -------------------------------
    s: Settings
    layout: CellLayout
    ports: Ports
    belt: BeltModel                    # where each material on the belt is
    now: float
    materials: Dict[int, Material]     # every material seen, by id
    home_q: Dict[str, np.ndarray]      # each arm's start (and end) pose, set by the loader
    lag: float                         # the longest a pick's plan has taken (real time) [s]
    loaded: int                        # materials put on the youBot's plate

    # --- the record ---------------------------------------------------------------------------
    def event(self, now: float, kind: EventKind, robot: str = '', m: Optional[Material] = None,
              detail: str = '') -> None: ...

    def fail(self, now: float, m: Material, kind: EventKind, why: str, robot: str) -> None: ...

    def count_grasp(self, arm: str, success: bool = False) -> None: ...

    # --- the arms' motions --------------------------------------------------------------------
    def limits(self, arm: str) -> JointLimits: ...

    def plan(self, arm: str, q: Vector, waypoints: Sequence[Waypoint],
             wait: float = 0.0, start: Optional[float] = None) -> Points: ...

    def plan_home(self, arm: str, obs: Observation, ready: bool = False) -> None: ...

    def send(self, motion: Motion, start: Optional[float] = None) -> None: ...

    def send_continuing(self, arm: str, now: float, t1: float, points: Points) -> None: ...

    def has_motion(self, arm: str) -> bool: ...

    def motion(self, arm: str) -> Motion: ...

    def arrived(self, arm: str, q: np.ndarray, now: float,
                dq: Optional[np.ndarray] = None) -> Optional[bool]: ...

    def arrival_time(self, arm: str, q: np.ndarray) -> float: ...

    def solve(self, arm: str, position: Vector, orientation: Vector, frame: str,
              seed: Vector) -> Optional[np.ndarray]: ...

    def solve_path(self, arm: str, positions: Sequence[Vector],
                   seed: Vector) -> Optional[List[np.ndarray]]: ...

    def solve_tilted(self, points: Sequence[np.ndarray], seed: np.ndarray,
                     payload: float = 0.0,
                     held_from: int = 0) -> Optional[List[np.ndarray]]: ...

    # --- what is still to come, and where it can go -------------------------------------------
    def to_come(self, name: str) -> int: ...

    def to_come_counts(self) -> Dict[str, int]: ...

    def carried_to_come(self) -> int: ...

    def plate_taken(self, but: Optional[Material] = None) -> Dict[int, str]: ...

    def plate_slots(self, m: Material) -> List[int]: ...

    def loadable(self, m: Material) -> bool: ...

    def free_places(self, region: str, m: Material) -> List[int]: ...

    def set_down_rise(self, destination: Optional[str]) -> float: ...

    # --- the other machine --------------------------------------------------------------------
    @property
    def loader_done(self) -> bool:
        """The Zu 12 has nothing more to load (it is home or on its way)."""
        ...

    def zu12_clear_of_the_plate(self, now: float) -> bool:
        """The Zu 12's cup is clear of the youBot's plate: the base may move."""
        ...
