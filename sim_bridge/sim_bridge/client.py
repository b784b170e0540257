"""A PyBullet client whose functions are bound once.

pybullet_utils' BulletClient binds its client id into a PyBullet function on every attribute
access: a new functools.partial, after asking ``inspect`` whether the name is a builtin, about
1.5 us a call. A cell's step makes dozens of calls (contacts, poses, velocities, motor commands),
and a trial 15 000 steps.
"""
from __future__ import annotations

import functools
from typing import Any

from pybullet_utils.bullet_client import BulletClient


# (pybullet_utils ships no types: its BulletClient is Any to mypy.)
class Client(BulletClient):  # type: ignore[misc]
    """BulletClient that keeps each bound function it made; ``disconnect`` forgets them (a
    client id is reused by the next connection)."""

    def __getattr__(self, name: str) -> Any:
        attribute = super().__getattr__(name)
        if name == 'disconnect':
            for key in [k for k, v in vars(self).items() if isinstance(v, functools.partial)]:
                del self.__dict__[key]
        elif isinstance(attribute, functools.partial):
            self.__dict__[name] = attribute
        return attribute
