"""The world's ``conveyor`` section: the belt, and its drive's encoder if the cell has one."""
from __future__ import annotations

from typing import Any

from world_description.world_schema import (
    TURN_RAD,
    BeltEncoderConfig,
    ConveyorConfig,
    Reader,
)


def conveyor_section(r: Reader, item: Any) -> ConveyorConfig:
    where = 'conveyor'
    r.only(item, where, {'position', 'length', 'width', 'yaw', 'belt_speed', 'end_stop',
                         'encoder'})
    end_stop = item.get('end_stop', False)
    if not isinstance(end_stop, bool):
        raise r.fail(where, 'end_stop', f'must be true or false, got {end_stop!r}')
    encoder = None
    if item.get('encoder') is not None:
        enc, at = item['encoder'], f'{where}.encoder'
        r.only(enc, at, {'resolution', 'noise', 'rate'})
        encoder = BeltEncoderConfig(
            resolution=r.number(enc, 'resolution', at, default=1.0e-4, lo=1.0e-6, hi=0.01),
            noise=r.number(enc, 'noise', at, default=0.0, lo=0.0, hi=0.1),
            rate=r.number(enc, 'rate', at, default=10.0, lo=0.5, hi=1000.0))
    return ConveyorConfig(position=r.vec3(item, 'position', where),
                          length=r.number(item, 'length', where, lo=0.1, hi=50.0),
                          width=r.number(item, 'width', where, lo=0.02, hi=5.0),
                          yaw=r.number(item, 'yaw', where, default=0.0, lo=-TURN_RAD,
                                       hi=TURN_RAD),
                          belt_speed=r.number(item, 'belt_speed', where, default=0.05, lo=0.0,
                                              hi=2.0), end_stop=end_stop, encoder=encoder)
