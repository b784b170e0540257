"""Joints that never move faster than their limits: the brake of a geared joint at its speed.

A PyBullet position or velocity motor caps the speed it *asks* for at the URDF's velocity
limit, but it may only push with the URDF's effort: gravity on a heavy arm, a load let go, a
contact or the reaction of another joint can drive a joint past its limit, and the joint
states would show it. A real joint cannot: its motor turns it through a high-reduction gearbox
that is hard to back-drive, and its drive brakes the motor at its rated speed. After every
physics step, :class:`SpeedLimiter` does what that brake does: each joint found faster than its
limit is brought back to its limit exactly, and every other joint keeps its speed (PhysX's
articulations clamp a joint's speed the same way).

Keeping the other joints' speeds is the gears' doing too: a brake acting alone at one joint of
a free chain would hand its link's momentum to the joints beyond it (braking the Zu 12's
shoulder from 4 to 2.1 rad/s would swing its elbow and wrists to 2 rad/s and more), but each of
those is a geared joint that resists being driven as much as the braked one. The generalised
impulse the change took (M dv, through the body's mass matrix; a mobile robot's base taken as
held by its wheels) gives each braking's mean brake torque over the step, which is returned
with the speed the joint would have had, so that the simulator can say when the world drove a
joint past its limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from pybullet_utils.bullet_client import BulletClient


@dataclass(frozen=True)
class Braked:
    """A joint brought back to its speed limit after a step.

    ``speed`` is what the step left it at (signed, in the joint's reported units: rad/s or
    m/s), ``limit`` its limit, ``torque`` the mean brake torque [N m] or force [N] over the step
    that brought it back.
    """

    joint: str
    speed: float
    limit: float
    torque: float
    torque_is_force: bool = False       # a prismatic joint's brake is a force [N]
    effort: float = math.inf            # the joint's own effort limit (its motor's most)

    @property
    def driven_past(self) -> bool:
        """Driven past its limit by the world: well past it (more than DRIVEN_PAST), and it
        took a brake torque beyond what the joint's own motor gives. Short of either, the
        brake only took out the solver's slop (a motor asked for its limit overshoots it by up
        to 0.8 %; a finger nudged by the material it closes on takes a fraction of a newton)."""
        return self.ratio > 1.0 + DRIVEN_PAST and self.torque > self.effort

    @property
    def ratio(self) -> float:
        return abs(self.speed) / self.limit


class SpeedLimiter:
    """Holds every limited joint of one body at or below its velocity limit (see the module)."""

    def __init__(self, client: BulletClient, body: int, joints: Sequence[int],
                 names: Sequence[str], limits: Sequence[float], scales: Sequence[float],
                 floating_base: bool, time_step: float,
                 prismatic: Sequence[bool] = (), efforts: Sequence[float] = ()) -> None:
        """``joints``: the body's movable joints (PyBullet indices, in its order), ``limits``
        their velocity limits in reported units (<= 0: none), ``scales`` reported speed over
        PyBullet joint speed (a virtual omni-wheel's is sqrt(2))."""
        self._p, self._body = client, body
        self._joints = list(joints)
        self._names = list(names)
        self._scales = np.asarray(scales, float)
        reported = np.asarray(limits, float)
        self._reported = np.where(reported > 0.0, reported, np.inf)
        self._limit = self._reported / self._scales          # in PyBullet's joint units
        self._limits = self._limit.tolist()
        self._floating = floating_base
        self._dt = time_step
        self._prismatic = list(prismatic) or [False] * len(self._joints)
        self._efforts = [e if e > 0.0 else math.inf for e in efforts] or [math.inf] * len(
            self._joints)

    @property
    def active(self) -> bool:
        return bool(np.isfinite(self._limit).any())

    def enforce(self) -> List[Braked]:
        """Bring every joint faster than its limit back to it; what was braked."""
        if not self.active:
            return []
        states = self._p.getJointStates(self._body, self._joints)
        # (The common case, every joint within its limit, in plain Python: a step costs
        # PyBullet about 0.4 ms, and numpy's calls on a dozen numbers would add a tenth.)
        if all(-lim <= st[1] <= lim for st, lim in zip(states, self._limits)):
            return []
        v = np.array([s[1] for s in states])
        over = np.abs(v) > self._limit
        if not over.any() or not np.all(np.isfinite(v)):
            return []              # (a state that is not finite is the runner's to handle)
        q = [s[0] for s in states]
        after = np.clip(v, -self._limit, self._limit)
        for k in np.flatnonzero(over):
            self._p.resetJointState(self._body, self._joints[k], q[k], float(after[k]))
        # The generalised impulse that change took (M dv): at a braked joint, its brake's.
        mass = np.asarray(self._p.calculateMassMatrix(self._body, q), float)
        if self._floating:
            mass = mass[6:, 6:]
        impulse = mass @ (after - v)
        before = v
        return [Braked(self._names[k], float(before[k] * self._scales[k]),
                       float(self._reported[k]),
                       float(abs(impulse[k]) / self._dt / self._scales[k]),
                       self._prismatic[k], self._efforts[k])
                for k in np.flatnonzero(over)]


# A joint the step left more than this fraction over its limit, with a brake beyond its motor's
# effort, was driven past it by the world (Braked.driven_past).
DRIVEN_PAST = 0.02


@dataclass
class _Joint:
    brakings: int = 0
    driven: int = 0              # brakings more than DRIVEN_PAST over the limit
    worst: Optional[Braked] = None
    worst_time: float = 0.0      # [s of simulated time]


class BrakeBook:
    """What the brakes did, per robot and joint, since the start or the last reset: the
    simulator's log lines and its diagnostics."""

    def __init__(self) -> None:
        self._joints: Dict[Tuple[str, str], _Joint] = {}

    def clear(self) -> None:
        self._joints.clear()

    def add(self, robot: str, time_s: float, braked: Sequence[Braked]) -> List[str]:
        """Book the brakings of one step; a line for each joint the world drove past its
        limit."""
        lines = []
        for b in braked:
            entry = self._joints.setdefault((robot, b.joint), _Joint())
            entry.brakings += 1
            if not b.driven_past:
                continue
            entry.driven += 1
            if entry.worst is None or b.ratio > entry.worst.ratio:
                entry.worst, entry.worst_time = b, time_s
            unit = 'N' if b.torque_is_force else 'N m'
            lines.append(f'{robot}: {b.joint} was driven past its speed limit at {time_s:.3f} s:'
                         f' {abs(b.speed):.4g} ({b.ratio:.3f} times its {b.limit:.4g}); braked '
                         f'back to it with {b.torque:.3g} {unit} (its motor: {b.effort:.3g})')
        return lines

    def driven(self, robot: str) -> List[Tuple[str, _Joint]]:
        """The joints of a robot driven past their limits, worst first."""
        out = [(joint, e) for (r, joint), e in self._joints.items()
               if r == robot and e.worst is not None]
        return sorted(out, key=lambda item: -item[1].worst.ratio if item[1].worst else 0.0)

    def status(self, robot: str) -> Tuple[bool, str, List[Tuple[str, str]]]:
        """(any driven past, message, key-values) for a robot's diagnostic status; the values
        per joint driven past: ``<joint>/ratio``, ``/speed``, ``/limit``, ``/brake``,
        ``/time``, ``/count``."""
        driven = self.driven(robot)
        brakings = sum(e.brakings for (r, _), e in self._joints.items() if r == robot)
        values: List[Tuple[str, str]] = [('brakings', str(brakings))]
        for joint, e in driven:
            assert e.worst is not None
            values += [(f'{joint}/ratio', f'{e.worst.ratio:.4f}'),
                       (f'{joint}/speed', f'{abs(e.worst.speed):.10g}'),
                       (f'{joint}/limit', f'{e.worst.limit:.10g}'),
                       (f'{joint}/brake', f'{e.worst.torque:.10g}'),
                       (f'{joint}/time', f'{e.worst_time:.4f}'),
                       (f'{joint}/count', str(e.driven))]
        if not driven:
            return False, f'no joint driven past its speed limit ({brakings} brakings at it)', \
                values
        joint, e = driven[0]
        assert e.worst is not None
        return True, (f'{len(driven)} joint(s) driven past their speed limits; the worst '
                      f'{joint}, {e.worst.ratio:.3f} times its limit at {e.worst_time:.2f} s'), \
            values
