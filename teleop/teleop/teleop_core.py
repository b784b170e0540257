"""Teleop logic without ROS: the report's buttons as keys, speed control, and timed scripts."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

# The report's buttons. Keys follow teleop_twist_keyboard's layout (i/,/j/l/k) and also WASD.
MOTIONS: Dict[str, Tuple[float, float, float]] = {
    # name: fractions of (linear speed along x, along y, turn rate)
    'forward': (1.0, 0.0, 0.0),
    'backward': (-1.0, 0.0, 0.0),
    'left': (0.0, 0.0, 1.0),
    'right': (0.0, 0.0, -1.0),
    'strafe_left': (0.0, 1.0, 0.0),
    'strafe_right': (0.0, -1.0, 0.0),
    'stop': (0.0, 0.0, 0.0),
}
HOLONOMIC_MOTIONS = ('strafe_left', 'strafe_right')
KEY_BINDINGS: Dict[str, str] = {
    'i': 'forward', 'w': 'forward',
    ',': 'backward', 'x': 'backward',
    'j': 'left', 'a': 'left',
    'l': 'right', 'd': 'right',
    'k': 'stop', 's': 'stop', ' ': 'stop',
}
# Strafing, for holonomic (Mecanum) bases: teleop_twist_keyboard's shifted J/L, and Q/E.
HOLONOMIC_KEY_BINDINGS: Dict[str, str] = {
    'J': 'strafe_left', 'q': 'strafe_left',
    'L': 'strafe_right', 'e': 'strafe_right',
}
SPEED_KEYS: Dict[str, float] = {'+': 0.1, '=': 0.1, '-': -0.1, '_': -0.1}

HELP = """\
Mini robot teleop (keys act immediately; the command repeats until changed)
  i / w : forward        , / x : backward
  j / a : turn left      l / d : turn right
  k / s / space : stop
  + / - : speed up / down by 10 % of max   (replaces the report's slider)
  Ctrl-C: quit (a zero twist is sent)
"""
HOLONOMIC_HELP = """\
  J / q : strafe left    L / e : strafe right   (holonomic mode)
"""


class TeleopError(ValueError):
    """A teleop script or setting that cannot be used."""


@dataclass
class TeleopState:
    """Current motion and speed level; produces the twist to publish."""

    max_speed: float
    max_turn: float
    # The report's buttons drive at half of max_speed.
    speed_fraction: float = 0.5
    motion: str = 'stop'
    holonomic: bool = False

    def __post_init__(self) -> None:
        for name in ('max_speed', 'max_turn'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise TeleopError(f'{name} must be finite and > 0, got {value}')
        self.speed_fraction = _clip_fraction(self.speed_fraction)

    def press(self, key: str) -> Optional[str]:
        """Apply a key press; return a short description of what changed, or None."""
        if key in KEY_BINDINGS:
            self.motion = KEY_BINDINGS[key]
            return self.motion
        if self.holonomic and key in HOLONOMIC_KEY_BINDINGS:
            self.motion = HOLONOMIC_KEY_BINDINGS[key]
            return self.motion
        if key in SPEED_KEYS:
            self.speed_fraction = _clip_fraction(self.speed_fraction + SPEED_KEYS[key])
            return f'speed {self.speed_fraction:.0%}'
        return None

    def twist(self) -> Tuple[float, float, float]:
        """(vx, vy, wz) of the current motion at the current speed level."""
        x, y, ang = MOTIONS[self.motion]
        return (x * self.speed_fraction * self.max_speed, y * self.speed_fraction * self.max_speed,
                ang * self.speed_fraction * self.max_turn)


def _clip_fraction(value: float) -> float:
    return round(min(1.0, max(0.0, value)), 6)


@dataclass(frozen=True)
class ScriptStep:
    """One step of a timed script: a twist (v, w, and vy for holonomic bases) held for
    ``duration`` seconds of simulated time."""

    name: str
    v: float
    w: float
    duration: float
    vy: float = 0.0


@dataclass
class TeleopScript:
    steps: List[ScriptStep] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.steps)

    def command_at(self, t: float) -> Optional[ScriptStep]:
        """The step active ``t`` seconds after the script started, or None when finished."""
        elapsed = 0.0
        for step in self.steps:
            elapsed += step.duration
            if t < elapsed:
                return step
        return None


_DURATION = re.compile(r'^(?P<value>[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(?P<unit>ms|s)?$')


def parse_script(text: str, max_speed: float, max_turn: float,
                 speed_fraction: float = 0.5, holonomic: bool = False) -> TeleopScript:
    """Parse a timed script such as ``forward 2s, left 1.5s, speed 0.8, stop``.

    Statements are separated by commas, semicolons or newlines. Motions are ``forward``,
    ``backward``, ``left``, ``right`` and ``stop`` with an optional duration (``2``, ``2s``,
    ``500ms``; ``stop`` defaults to 0 s), and ``strafe_left``/``strafe_right`` with
    ``holonomic``; ``speed F`` sets the fraction of the maximum speed
    used by the following motions (the report's slider), and ``twist V W DURATION`` sends an
    explicit twist. Raises TeleopError with the offending statement on any mistake.
    """
    state = TeleopState(max_speed, max_turn, speed_fraction, holonomic=holonomic)
    script = TeleopScript()
    statements = [s.strip() for s in re.split(r'[,;\n]', text) if s.strip()]
    if not statements:
        raise TeleopError('the script is empty')
    for stmt in statements:
        words = stmt.split()
        verb = words[0].lower()
        try:
            if verb in HOLONOMIC_MOTIONS and not holonomic:
                raise TeleopError(f'"{verb}" needs holonomic mode (a Mecanum base)')
            if verb in MOTIONS:
                if len(words) > 2:
                    raise TeleopError('expected "<motion> [duration]"')
                if len(words) == 1 and verb != 'stop':
                    raise TeleopError('a motion needs a duration, e.g. "forward 2s"')
                duration = _parse_duration(words[1]) if len(words) == 2 else 0.0
                state.motion = verb
                v, vy, w = state.twist()
                script.steps.append(ScriptStep(verb, v, w, duration, vy))
            elif verb == 'speed':
                if len(words) != 2:
                    raise TeleopError('expected "speed <fraction 0..1>"')
                fraction = float(words[1])
                if not (0.0 <= fraction <= 1.0):
                    raise TeleopError(f'speed fraction must be within 0..1, got {fraction}')
                state.speed_fraction = fraction
            elif verb == 'twist':
                if len(words) != 4:
                    raise TeleopError('expected "twist <v m/s> <w rad/s> <duration>"')
                v, w = float(words[1]), float(words[2])
                if not (math.isfinite(v) and math.isfinite(w)):
                    raise TeleopError('twist values must be finite')
                script.steps.append(ScriptStep('twist', v, w, _parse_duration(words[3])))
            else:
                raise TeleopError(f'unknown command "{verb}"')
        except (TeleopError, ValueError) as exc:
            raise TeleopError(f'bad script statement "{stmt}": {exc}') from None
    return script


def _parse_duration(word: str) -> float:
    match = _DURATION.match(word.strip().lower())
    if not match:
        raise TeleopError(f'bad duration "{word}" (use e.g. 2s, 1.5, 500ms)')
    value = float(match.group('value'))
    return value / 1000.0 if match.group('unit') == 'ms' else value
