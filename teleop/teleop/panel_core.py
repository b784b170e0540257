"""The control panel's logic without ROS: the robots a page can drive, what a page may send,
and the dead-man rule.

The panel is the mini robot report's interface: buttons forward, backward, left, right and
stop, and a speed slider that sets the fraction of ``max_speed`` (and of ``max_turn`` for turns,
as the teleop node's speed level does). The report's own turn buttons run the wheels at
±0.5·max_speed/r, a turn rate of max_speed/wheel_separation at the slider's middle
(``report_turns``). A holonomic base (the youBot's Mecanum drive) adds strafing.

Dead man: a page drives only while it holds a button, and says so at least every
``heartbeat`` seconds. A release, a stop, a silent page (``deadman_timeout``) or a page that goes
away stops the robot with one zero twist; past that the simulator's ``cmd_vel_timeout`` stops
it even if the panel itself dies.
"""
from __future__ import annotations

import collections
import json
import math
from dataclasses import dataclass
from typing import Any, Deque, Dict, List, Optional, Tuple

from teleop.teleop_core import HOLONOMIC_MOTIONS, MOTIONS, TeleopState
from world_description.world_config import DiffDriveConfig, MecanumConfig, WorldConfig

MAX_MESSAGE_BYTES = 4096


class PanelInputError(ValueError):
    """A message from a page that is not one the panel takes."""


@dataclass(frozen=True)
class PanelRobot:
    """A base the panel can drive: its namespace and the limits its buttons use."""

    name: str
    namespace: str
    holonomic: bool
    max_speed: float
    max_turn: float
    wheel_separation: Optional[float] = None      # diff drive: the report's turn buttons
    camera: str = ''                              # image topic shown beside it ('' none)

    @property
    def cmd_vel(self) -> str:
        return f'{self.namespace}/cmd_vel'

    @property
    def odom(self) -> str:
        return f'{self.namespace}/odom'

    def describe(self) -> Dict[str, Any]:
        return {'name': self.name, 'namespace': self.namespace, 'holonomic': self.holonomic,
                'max_speed': self.max_speed, 'max_turn': self.max_turn,
                'report_turns': self.wheel_separation is not None, 'camera': self.camera}


def _ns(namespace: str) -> str:
    return '/' + namespace.strip('/') if namespace.strip('/') else ''


def robots_of_world(world: WorldConfig, max_speed: float, max_turn: float) -> List[PanelRobot]:
    """Every driven base of a world, with the simulator's limits where its entry sets none,
    and the camera it carries (else the world's first fixed camera)."""
    fixed = [c for c in world.cameras if c.robot is None]
    robots = []
    for robot in world.robots:
        if robot.drive is None:
            continue
        ns = _ns(robot.namespace)
        own = [c for c in world.cameras if c.robot == robot.name]
        camera = (f'{ns}/{own[0].name}/image_raw' if own else
                  f'/{fixed[0].name}/image_raw' if fixed else '')
        separation = (robot.drive.wheel_separation if isinstance(robot.drive, DiffDriveConfig)
                      else None)
        robots.append(PanelRobot(
            robot.name, ns, isinstance(robot.drive, MecanumConfig),
            robot.limits.max_speed or max_speed, robot.limits.max_turn or max_turn,
            separation, camera))
    return robots


@dataclass(frozen=True)
class PanelCommand:
    op: str                         # hold, release, stop, speed, select, report_turns
    motion: str = ''
    fraction: float = 0.0
    namespace: str = ''
    on: bool = False


_OPS = ('hold', 'release', 'stop', 'speed', 'select', 'report_turns')
MAX_NAMESPACE = 256                 # characters of a namespace a page may name


def _fraction(value: Any) -> float:
    """A speed fraction: a JSON number within 0..1 (not a bool, a string, NaN, or an integer
    too large for a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PanelInputError(f'speed fraction must be a number within 0..1, got '
                              f'{_shown(value)}')
    try:
        fraction = float(value)
    except OverflowError:
        raise PanelInputError('speed fraction must be a number within 0..1, got an integer '
                              f'of {len(str(value))} digits') from None
    if not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
        raise PanelInputError(f'speed fraction must be a number within 0..1, got {fraction!r}')
    return fraction


def _shown(value: Any) -> str:
    """A value a page sent, for a reason: its type and the start of its JSON."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError, RecursionError):
        text = type(value).__name__
    return text if len(text) <= 40 else text[:37] + '...'


def parse_command(text: Any) -> PanelCommand:
    """A page's message (JSON text) as a command; raises PanelInputError with the reason.

    It is the one gate between a page and the node: whatever a page sends, the answer is a
    valid command or PanelInputError, never another exception (tested with hypothesis)."""
    if not isinstance(text, str):
        raise PanelInputError('messages are JSON text')
    if len(text) > MAX_MESSAGE_BYTES:
        raise PanelInputError(f'message of {len(text)} characters (at most {MAX_MESSAGE_BYTES})')
    try:
        data = json.loads(text)
    except RecursionError:
        raise PanelInputError('not JSON: nested too deeply') from None
    except ValueError as exc:       # (also an integer of more than 4300 digits)
        raise PanelInputError(f'not JSON: {str(exc)[:100]}') from None
    if not isinstance(data, dict) or not isinstance(data.get('op'), str) \
            or data['op'] not in _OPS:
        raise PanelInputError(f'expected {{"op": one of {list(_OPS)}, ...}}')
    op = data['op']
    if op == 'hold':
        motion = data.get('motion')
        if not isinstance(motion, str) or motion not in MOTIONS or motion == 'stop':
            raise PanelInputError(f'unknown motion {_shown(motion)}')
        return PanelCommand(op, motion=motion)
    if op == 'speed':
        return PanelCommand(op, fraction=_fraction(data.get('fraction')))
    if op == 'select':
        namespace = data.get('namespace')
        if not isinstance(namespace, str) or len(namespace) > MAX_NAMESPACE:
            raise PanelInputError(f'select needs a namespace (text of at most {MAX_NAMESPACE} '
                                  f'characters), got {_shown(namespace)}')
        return PanelCommand(op, namespace=namespace)
    if op == 'report_turns':
        on = data.get('on')
        if not isinstance(on, bool):
            raise PanelInputError(f'report_turns needs "on": true or false, got {_shown(on)}')
        return PanelCommand(op, on=on)
    return PanelCommand(op)


class Outbox:
    """What the panel owes one page, bounded whatever the page does: the latest of each kind
    of news (a newer state replaces one not yet sent; the page needs only the latest), and the
    last few refusals. A page that does not read costs the panel this much and no more, and
    its sender never holds up another page's."""

    LATEST = ('error', 'hello', 'state', 'frame')     # sent in this order
    MAX_REFUSALS = 8

    def __init__(self) -> None:
        self._latest: Dict[str, Any] = {}
        self._refusals: Deque[str] = collections.deque(maxlen=self.MAX_REFUSALS)
        self.dropped = 0            # news replaced or refusals dropped before they were sent

    def put(self, kind: str, data: Any) -> None:
        if kind not in self.LATEST:
            raise ValueError(f'unknown kind {kind!r}')
        if kind in self._latest:
            self.dropped += 1
        self._latest[kind] = data

    def refuse(self, text: str) -> None:
        if len(self._refusals) == self.MAX_REFUSALS:
            self.dropped += 1
        self._refusals.append(text)

    def __bool__(self) -> bool:
        return bool(self._latest or self._refusals)

    def take(self) -> Optional[Any]:
        """The next message to send (a JSON text or a frame's bytes), or None."""
        if self._refusals:
            return json.dumps({'op': 'refused', 'text': self._refusals.popleft()})
        for kind in self.LATEST:
            if kind in self._latest:
                return self._latest.pop(kind)
        return None


class DeadMan:
    """The command a panel publishes: a held motion while the page keeps saying so."""

    def __init__(self, robot: PanelRobot, deadman_timeout: float,
                 speed_fraction: float = 0.5, report_turns: bool = False) -> None:
        if not (math.isfinite(deadman_timeout) and deadman_timeout > 0.0):
            raise PanelInputError(f'deadman_timeout must be > 0, got {deadman_timeout}')
        self.timeout = deadman_timeout
        self.robot = robot
        self.state = TeleopState(robot.max_speed, robot.max_turn, speed_fraction,
                                 holonomic=robot.holonomic)
        self.report_turns = report_turns and robot.wheel_separation is not None
        self.holder: Optional[int] = None          # the page that holds a button
        self._deadline = -math.inf
        self._stop_due = False                     # a zero twist owed to the robot
        self.stops: List[str] = []                 # why it stopped, latest last

    @property
    def motion(self) -> str:
        return self.state.motion

    @property
    def speed_fraction(self) -> float:
        return self.state.speed_fraction

    def hold(self, motion: str, page: int, now: float) -> None:
        if motion in HOLONOMIC_MOTIONS and not self.robot.holonomic:
            raise PanelInputError(f'{motion} needs a holonomic base; '
                                  f'{self.robot.name} has a differential drive')
        self.state.motion, self.holder = motion, page
        self._deadline = now + self.timeout

    def release(self, page: int) -> None:
        """A page let go of its button: the holder's release stops the robot, another
        page's does not end the hold."""
        if self.holder in (None, page):
            self.stop('released')

    def stop(self, why: str) -> None:
        """Stop, whoever holds (the stop button, a silent page, another robot chosen)."""
        if self.state.motion != 'stop' or self.holder is not None:
            self._stop_due = True
            self.stops.append(why)
        self.state.motion, self.holder = 'stop', None
        self._deadline = -math.inf

    def gone(self, page: int) -> None:
        if self.holder == page:
            self.stop('the page went away')

    def set_speed(self, fraction: float) -> None:
        self.state.speed_fraction = round(min(1.0, max(0.0, fraction)), 6)

    def set_report_turns(self, on: bool) -> None:
        self.report_turns = on and self.robot.wheel_separation is not None

    def twist(self) -> Tuple[float, float, float]:
        vx, vy, wz = self.state.twist()
        if self.report_turns and self.state.motion in ('left', 'right'):
            # The report: each wheel at ±f·max_speed/r, so wz = 2·f·max_speed/separation.
            separation = self.robot.wheel_separation or 1.0
            sign = 1.0 if self.state.motion == 'left' else -1.0
            wz = sign * 2.0 * self.state.speed_fraction * self.robot.max_speed / separation
        return vx, vy, wz

    def tick(self, now: float) -> Optional[Tuple[float, float, float]]:
        """The twist to publish now, or None for nothing: a held motion while the page keeps
        saying so, one zero twist after it stops (for any reason)."""
        if self.state.motion != 'stop' and now > self._deadline:
            self.stop(f'no word from the page for {self.timeout:g} s')
        if self.state.motion != 'stop':
            return self.twist()
        if self._stop_due:
            self._stop_due = False
            return (0.0, 0.0, 0.0)
        return None
