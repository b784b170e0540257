"""Joint limits beyond a URDF's, from a joint_limits.yaml as MoveIt and ros2_control's
joint_limits write it::

    joint_limits:
      arm_joint_1: {has_acceleration_limits: true, max_acceleration: 6.0}

The simulator reads the acceleration limits (position, velocity and effort come from the
URDF); the cell's planner reads velocity (below the URDF's), acceleration and jerk limits.
"""
from __future__ import annotations

import math
import os
import stat
from pathlib import Path
from typing import Dict

import yaml


class JointLimitsError(ValueError):
    """A joint_limits file that cannot be used; the message names the file and the field."""


MAX_FILE_BYTES = 1024 * 1024         # the project's are a few hundred bytes
MAX_ACCELERATION = 1e4               # [rad/s^2 or m/s^2] (and velocities [rad/s or m/s])
MAX_JERK = 1e6                       # [rad/s^3 or m/s^3]


def load_acceleration_limits(path: Path) -> Dict[str, float]:
    """{joint: max_acceleration} for the joints whose has_acceleration_limits is true."""
    return {joint: values['acceleration']
            for joint, values in load_joint_limits(path).items() if 'acceleration' in values}


# The limits read, by their MoveIt names: has_<flag>, max_<key>.
_LIMITS = (('velocity', 'has_velocity_limits', 'max_velocity'),
           ('acceleration', 'has_acceleration_limits', 'max_acceleration'),
           ('jerk', 'has_jerk_limits', 'max_jerk'))


def load_joint_limits(path: Path) -> Dict[str, Dict[str, float]]:
    """{joint: {'velocity' | 'acceleration' | 'jerk': limit}} for the limits whose has_*_limits
    flag is true (a velocity limit here lowers the URDF's for planning: the simulator keeps
    the URDF's)."""
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_FILE_BYTES:
            raise JointLimitsError(f'{path}: not a regular file of at most {MAX_FILE_BYTES} '
                                   'bytes')
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError) as exc:
        raise JointLimitsError(f'{path}: cannot be read as YAML: {exc}') from None
    joints = data.get('joint_limits') if isinstance(data, dict) else None
    if not isinstance(joints, dict):
        raise JointLimitsError(f'{path}: needs a "joint_limits" mapping of joint names')
    limits: Dict[str, Dict[str, float]] = {}
    for joint, entry in joints.items():
        if not isinstance(entry, dict):
            raise JointLimitsError(f'{path}: joint_limits.{joint} must be a mapping')
        for name, has, key in _LIMITS:
            flag = entry.get(has, False)
            if not isinstance(flag, bool):
                raise JointLimitsError(f'{path}: joint_limits.{joint}.{has} must be true or '
                                       f'false, got {flag!r}')
            if not flag:
                continue
            value = entry.get(key)
            top = MAX_JERK if name == 'jerk' else MAX_ACCELERATION
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not (math.isfinite(value) and 0.0 < value <= top)):
                raise JointLimitsError(f'{path}: joint_limits.{joint}.{key} must be a number '
                                       f'within (0, {top:g}], got {value!r}')
            limits.setdefault(str(joint), {})[name] = float(value)
    return limits
