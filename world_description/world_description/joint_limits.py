"""Joint limits beyond a URDF's, from a joint_limits.yaml as MoveIt and ros2_control's
joint_limits write it::

    joint_limits:
      arm_joint_1: {has_acceleration_limits: true, max_acceleration: 6.0}

Only the acceleration limits are read (position, velocity and effort come from the URDF).
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
MAX_ACCELERATION = 1e4               # [rad/s^2 or m/s^2]


def load_acceleration_limits(path: Path) -> Dict[str, float]:
    """{joint: max_acceleration} for the joints whose has_acceleration_limits is true."""
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
    limits: Dict[str, float] = {}
    for joint, entry in joints.items():
        if not isinstance(entry, dict):
            raise JointLimitsError(f'{path}: joint_limits.{joint} must be a mapping')
        flag = entry.get('has_acceleration_limits', False)
        if not isinstance(flag, bool):
            raise JointLimitsError(f'{path}: joint_limits.{joint}.has_acceleration_limits must '
                                   f'be true or false, got {flag!r}')
        if not flag:
            continue
        value = entry.get('max_acceleration')
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not (math.isfinite(value) and 0.0 < value <= MAX_ACCELERATION)):
            raise JointLimitsError(f'{path}: joint_limits.{joint}.max_acceleration must be a '
                                   f'number within (0, {MAX_ACCELERATION:g}], got {value!r}')
        limits[str(joint)] = float(value)
    return limits
