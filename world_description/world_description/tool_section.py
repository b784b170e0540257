"""A robot's ``suction`` entry: its grip tool (world_schema's SuctionConfig), the tool an arm's
kinematics solve for: a link, the tool's point in it, and whether it may turn about its axis."""
from __future__ import annotations

import re
from typing import Any, Dict

from world_description.ros_names import MAX_TOKEN_LENGTH
from world_description.world_schema import Reader, SuctionConfig

# The tool's point lies within this of its link's origin [m].
OFFSET_REACH_M = 1.0


def suction_section(r: Reader, item: Any, where: str) -> SuctionConfig:
    r.only(item, where, {'link', 'reach', 'max_payload', 'service', 'offset', 'free_yaw'})
    x, y, z = r.vector(item, 'offset', where, 3, lo=-OFFSET_REACH_M, hi=OFFSET_REACH_M,
                       default=(0.0, 0.0, 0.0))
    suction = SuctionConfig(r.string(item, 'link', where),
                            r.number(item, 'reach', where, default=0.01, lo=1e-4, hi=0.1),
                            r.number(item, 'max_payload', where, default=12.0, lo=1e-3,
                                     hi=1000.0),
                            r.string(item, 'service', where, default='suction'),
                            (x, y, z), _flag(r, item, 'free_yaw', where))
    if not (len(suction.service) <= MAX_TOKEN_LENGTH
            and re.fullmatch(r'[a-z][a-z0-9_]*(/[a-z][a-z0-9_]*)*', suction.service)):
        raise r.fail(where, 'service', f'{suction.service[:80]!r} is not a relative ROS name '
                     f'of at most {MAX_TOKEN_LENGTH} characters')
    return suction


def _flag(r: Reader, item: Dict[str, Any], key: str, where: str) -> bool:
    value = item.get(key, False)
    if not isinstance(value, bool):
        raise r.fail(where, key, f'must be true or false, got {value!r}')
    return value
