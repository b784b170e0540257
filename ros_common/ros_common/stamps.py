"""Time stamps and durations of messages (``builtin_interfaces/Time`` and ``Duration``, or any
message with ``sec`` and ``nanosec``) to and from integer nanoseconds and float seconds.

Integer nanoseconds are exact, so a stamp round-trips; seconds are for people and plots.
"""
from __future__ import annotations

import math

from builtin_interfaces.msg import Duration, Time

NS_PER_S = 1_000_000_000
# A Duration's sec is an int32: the longest duration a message can carry [s].
MAX_DURATION_S = 2**31 - 1


def to_ns(stamp) -> int:
    """Nanoseconds of a Time or Duration (or anything with ``sec`` and ``nanosec``)."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def to_seconds(stamp) -> float:
    """Seconds of a Time or Duration."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_from_ns(ns: int) -> Time:
    """A Time of ``ns`` nanoseconds (>= 0)."""
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def duration_from_ns(ns: int) -> Duration:
    """A Duration of ``ns`` nanoseconds (>= 0)."""
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Duration(sec=sec, nanosec=nanosec)


def set_stamp(stamp, ns: int) -> None:
    """Set a Time or Duration field in place to ``ns`` nanoseconds."""
    stamp.sec, stamp.nanosec = divmod(int(ns), NS_PER_S)


def duration_from_seconds(seconds: float) -> Duration:
    """A Duration of ``seconds``, rounded to the nanosecond; ValueError when it is not finite,
    negative, or longer than a Duration holds (its sec is an int32)."""
    if not math.isfinite(seconds) or not 0.0 <= seconds <= MAX_DURATION_S:
        raise ValueError(f'a duration must be within 0..{MAX_DURATION_S} s, got {seconds!r}')
    sec, nanosec = divmod(round(seconds * NS_PER_S), NS_PER_S)
    return Duration(sec=sec, nanosec=nanosec)


def clock_seconds(node) -> float:
    """The node's clock (simulated time with use_sim_time) in seconds."""
    return node.get_clock().now().nanoseconds * 1e-9
