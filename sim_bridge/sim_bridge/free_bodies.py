"""What keeps a body's physics state finite: the limits past which a body has left the world,
and the check of one body's state against them.

Every state set from outside is held to tighter limits before it reaches the physics
(entities.py: 50 m/s, 50 rad/s); these catch what the physics itself does with it. A
velocity that is finite and bounded, integrated over one step from a finite pose, gives a
finite pose: so the velocities of the free bodies (materials, spawned bodies) and of the
robots' bases are checked after every step, and their poses at the state rate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pybullet_utils.bullet_client import BulletClient

# PyBullet caps every velocity coordinate of a body at 100 (m/s, rad/s: its multibodies'
# maxCoordinateVelocity) and integrates on from the capped value: a body at the cap moves as
# the engine can no longer say, and one pushed further (1e300 m/s) goes NaN at once.
VELOCITY_CAP = 100.0
AT_CAP = 0.99 * VELOCITY_CAP
WORLD_RADIUS_M = 1000.0          # a body farther than this from the origin has left the world


@dataclass(frozen=True)
class Lost:
    """A body taken out of the world after a step (or a static one put back), and what was
    done and why."""
    name: str
    what: str


_AT_CAP_2 = AT_CAP * AT_CAP


def moving_within_reason(client: BulletClient, body: int) -> bool:
    """The quick test after every step (about 1.5 us): both speeds finite and below the cap
    (a NaN fails the comparison). False means: ask base_problem."""
    v, w = client.getBaseVelocity(body)
    return bool(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < _AT_CAP_2
                and w[0] * w[0] + w[1] * w[1] + w[2] * w[2] < _AT_CAP_2)


def base_problem(client: BulletClient, body: int, pose: bool = True) -> str:
    """What is wrong with a body's base state ('' if nothing): not finite, at the engine's
    velocity cap, or (with ``pose``) too far. About 2 us without the pose, 4.5 us with it."""
    v, w = client.getBaseVelocity(body)
    fastest = max(abs(v[0]), abs(v[1]), abs(v[2]), abs(w[0]), abs(w[1]), abs(w[2]))
    if not math.isfinite(fastest):
        return 'its velocity is not finite'
    if fastest >= AT_CAP:
        return (f'its velocity reached {fastest:.4g} (m/s or rad/s), PyBullet\'s cap of '
                f'{VELOCITY_CAP:g}: its motion is no longer simulated')
    if pose:
        p, q = client.getBasePositionAndOrientation(body)
        if not math.isfinite(sum(p) + sum(q)):
            return 'its pose is not finite'
        distance = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        if distance > WORLD_RADIUS_M:
            return f'it was {distance:.4g} m from the origin (beyond {WORLD_RADIUS_M:g})'
    return ''
