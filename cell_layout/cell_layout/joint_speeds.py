"""Each robot's joint speed limits as its URDF gives them, and the simulator's account of the
joints it braked back to them (its ``~/joint_limits`` diagnostics), for a trial's result."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, List

from world_description.resources import resolve_resource
from world_description.urdf_check import read_urdf_file, summarise_urdf
from world_description.world_config import WorldConfig

# The per-joint values of a robot's status (sim_bridge.joint_speed.BrakeBook.status).
_FIELDS = ('ratio', 'speed', 'limit', 'brake', 'time', 'count')


def speed_limits(world: WorldConfig, robot: str) -> Dict[str, float]:
    """Every moving joint of the robot's URDF with a speed limit: name -> limit (rad/s or
    m/s), in the URDF's order."""
    config = next((rc for rc in world.robots if rc.name == robot), None)
    if config is None:
        return {}
    base_dir = Path(world.source).parent if world.source else None
    summary = summarise_urdf(read_urdf_file(resolve_resource(config.urdf, base_dir)))
    return {j.name: j.velocity for j in summary.joint_list
            if j.kind != 'fixed' and j.velocity > 0.0 and math.isfinite(j.velocity)}


def driven_past(statuses: Any) -> List[Dict[str, Any]]:
    """The joints a DiagnosticArray of the simulator's ``~/joint_limits`` names as driven past
    their speed limits: one record per joint (its worst: ``ratio``, ``speed``, ``limit``,
    ``brake`` torque or force, ``time`` [s of simulated time], ``count``), worst first; values
    that do not read as numbers are left out."""
    out = []
    for status in getattr(statuses, 'status', ()):
        values = {kv.key: kv.value for kv in status.values}
        joints = sorted({k.rsplit('/', 1)[0] for k in values if '/' in k})
        for joint in joints:
            record: Dict[str, Any] = {'robot': str(status.hardware_id), 'joint': joint}
            try:
                for name in _FIELDS:
                    number = float(values[f'{joint}/{name}'])
                    if not math.isfinite(number):
                        raise ValueError(name)
                    record[name] = int(number) if name == 'count' else number
            except (KeyError, ValueError):
                continue
            out.append(record)
    return sorted(out, key=lambda r: -r['ratio'])
