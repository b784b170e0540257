"""An accumulating belt with an end stop, as a model (no ROS, no physics engine).

The belt never stops. What it carries moves at the belt's speed until its front face meets the
end stop, or comes within a small gap of the back face of an item held ahead of it with which
it overlaps across the belt; from then on it stays where it is while the belt slides beneath it
(a zero-pressure accumulation conveyor: queued items never press on each other, so a corner of
the item ahead never pushes one sideways). Taking an item off releases the ones it held once it
is clear of them: an item being lifted blocks the lane until its bottom is above theirs.

The simulator applies this rule to the bodies on its belt each physics step, and the
coordinator predicts with it where the materials it saw are now and will be: both read it from
here, so that they agree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Sequence, Tuple

# An item whose front face is this close to where its blocker holds it counts as held [m].
CONTACT_TOLERANCE_M = 1e-3
# Queued items stop this far short of the item ahead (the end stop itself is met face to face):
# more than the belt moves in a physics step at trial speeds (0.16 m/s: 0.7 mm at 240 Hz), so
# that a queued item never touches the one ahead.
QUEUE_GAP_M = 3e-3


@dataclass(frozen=True)
class Item:
    along: float        # centre along the belt (distance from its upstream end) [m]
    across: float       # centre across the belt [m]
    length: float       # extent along the belt [m]
    width: float        # extent across the belt [m]


Blocker = Tuple[float, float, float]        # (back face along, centre across, width)


def _limit(it: Item, blockers: Sequence[Blocker], stop: float) -> float:
    """How far the item's front face may go: the stop, or the nearest back face ahead of it
    among the blockers it overlaps across the belt."""
    limit = stop
    for back, across, width in blockers:
        if abs(across - it.across) < (width + it.width) / 2:
            limit = min(limit, back - QUEUE_GAP_M)
    return limit


def _fixed(obstacles: Sequence[Item]) -> List[Blocker]:
    return [(ob.along - ob.length / 2, ob.across, ob.width) for ob in obstacles]


def _downstream_first(items: Sequence[Item]) -> List[int]:
    return sorted(range(len(items)), key=lambda i: -items[i].along)


def held(items: Sequence[Item], stop: float, obstacles: Sequence[Item] = ()) -> List[bool]:
    """Which items are held, at their present positions, by the stop (the along-coordinate
    of its face; ``math.inf`` for a belt without one), by a held item ahead of them, or by one
    of ``obstacles`` (in the lane but not carried: an item being lifted off)."""
    out = [False] * len(items)
    blockers = _fixed(obstacles)
    for k in _downstream_first(items):
        it = items[k]
        if it.along + it.length / 2 >= _limit(it, blockers, stop) - CONTACT_TOLERANCE_M:
            out[k] = True
            blockers.append((it.along - it.length / 2, it.across, it.width))
    return out


def advance(items: Sequence[Item], stop: float, travel: float,
            obstacles: Sequence[Item] = ()) -> List[float]:
    """Where the items' centres are (along) after the belt has moved ``travel`` [m]: each moves
    as far as the belt did, or up to its blocker, whichever is less. Items are processed from
    the most downstream, so a held one blocks those behind it."""
    if travel < 0.0 or not math.isfinite(travel):
        raise ValueError(f'travel must be finite and >= 0, got {travel}')
    out = [0.0] * len(items)
    blockers = _fixed(obstacles)
    for k in _downstream_first(items):
        it = items[k]
        target = _limit(it, blockers, stop) - it.length / 2   # where its blocker holds it
        out[k] = it.along if it.along >= target else min(it.along + travel, target)
        # Every item blocks the ones behind it where it ends up (moving items too: behind a
        # moving item an item moves at the same speed and never reaches it).
        blockers.append((out[k] - it.length / 2, it.across, it.width))
    return out
