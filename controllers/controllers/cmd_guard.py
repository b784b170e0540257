"""Safety filter for velocity commands: reject non-finite values, clamp, and time out."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

# A drive's wheel speeds for a command (rad/s): what a wheel speed limit is checked on.
WheelSpeeds = Callable[[Tuple[float, ...]], Sequence[float]]


@dataclass(frozen=True)
class GuardResult:
    """What the guard made of one command."""

    accepted: bool
    command: Tuple[float, ...]
    clamped: bool = False
    reason: str = ''
    wheel_limited: bool = False      # scaled down so that no wheel passes its speed limit


class CommandGuard:
    """Holds the last valid command and applies limits and a timeout (all times in seconds).

    The clock is the caller's (simulated time in the simulator), so the guard itself is pure.
    A rejected command zeroes the held command: a controller that sends garbage must not leave
    the robot driving on its previous command.
    """

    def __init__(self, limits: Sequence[float], timeout: float,
                 wheels: Optional[WheelSpeeds] = None, wheel_limit: float = math.inf) -> None:
        """``limits``: each component's (>= 0); ``wheels``: the drive's wheel speeds for a
        command, which a command is scaled down to keep within ``wheel_limit`` [rad/s] (its
        direction kept: a drive that saturates slows down along the same path)."""
        if not wheel_limit > 0.0:
            raise ValueError(f'wheel_limit must be > 0, got {wheel_limit}')
        if any(not (lim >= 0.0 and math.isfinite(lim)) for lim in limits) or not any(limits):
            raise ValueError(f'limits must be finite and >= 0 (0: the component stays 0), '
                             f'not all 0; got {list(limits)}')
        if not (timeout > 0.0 and math.isfinite(timeout)):
            raise ValueError(f'timeout must be finite and > 0, got {timeout}')
        self._limits = tuple(float(lim) for lim in limits)
        self._timeout = float(timeout)
        self._wheels, self._wheel_limit = wheels, float(wheel_limit)
        self._command = tuple(0.0 for _ in self._limits)
        self._stamp: Optional[float] = None

    @property
    def timeout(self) -> float:
        return self._timeout

    @property
    def limits(self) -> Tuple[float, ...]:
        return self._limits

    def submit(self, command: Sequence[float], now: float) -> GuardResult:
        if len(command) != len(self._limits):
            raise ValueError(f'expected {len(self._limits)} components, got {len(command)}')
        if not all(math.isfinite(c) for c in command):
            self.stop()
            return GuardResult(False, self._command,
                               reason=f'non-finite command {list(command)} rejected; stopping')
        clamped = tuple(max(-lim, min(lim, float(c))) for c, lim in zip(command, self._limits))
        fastest = (max((abs(w) for w in self._wheels(clamped)), default=0.0)
                   if self._wheels is not None else 0.0)
        wheel_limited = fastest > self._wheel_limit
        if wheel_limited:
            # (Wheel speeds are linear in the twist; the factor leaves the fastest one a hair
            # under its limit whatever the rounding.)
            factor = self._wheel_limit / fastest * (1.0 - 1e-12)
            clamped = tuple(c * factor for c in clamped)
        self._command = clamped
        self._stamp = now
        return GuardResult(True, clamped, clamped=clamped != tuple(float(c) for c in command),
                           wheel_limited=wheel_limited)

    def active_command(self, now: float) -> Tuple[float, ...]:
        """The command to apply at time ``now``: zero once the last one is older than timeout."""
        if self._stamp is None or now - self._stamp > self._timeout or now < self._stamp:
            return tuple(0.0 for _ in self._limits)
        return self._command

    def timed_out(self, now: float) -> bool:
        return self._stamp is not None and (now - self._stamp > self._timeout)

    def stop(self) -> None:
        self._command = tuple(0.0 for _ in self._limits)
        self._stamp = None


TWIST_FIELDS = ('linear.x', 'linear.y', 'linear.z', 'angular.x', 'angular.y', 'angular.z')


def non_finite_fields(values: Sequence[float], names: Sequence[str] = TWIST_FIELDS) -> str:
    """The fields of a message that are NaN or infinite, as 'angular.x=nan', or ''. A sender
    that puts one in any field, even one the robot does not use, is broken: stop."""
    return ', '.join(f'{n}={v}' for n, v in zip(names, values) if not math.isfinite(v))


def rate_limited(current: Sequence[float], target: Sequence[float],
                 max_steps: Sequence[float]) -> Tuple[float, ...]:
    """``target``, reached from ``current`` by at most ``max_steps`` per component (an
    acceleration limit times the time step), as ros2_controllers' speed limiter does."""
    return tuple(float(t) if abs(t - c) <= m else c + math.copysign(m, t - c)
                 for c, t, m in zip(current, target, max_steps))
