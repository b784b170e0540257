"""The run's clock (no ROS): the time of the observation being handled. The run sets it at
each tick; the parts read it (an arm plans from it, the log stamps with it)."""
from __future__ import annotations


class Clock:
    def __init__(self, start: float) -> None:
        self.start = start
        self.now = start
