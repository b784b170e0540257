"""World description files: robots, obstacles and cameras, loaded from YAML and validated.

The public face of the world package's reader. What a world holds is in ``world_schema``
(its dataclasses, the range of each number, the checking reader), how a file is read and
extended in ``world_loading``, and each section's parsing in ``world_sections``."""
from __future__ import annotations

from world_description.errors import WorldConfigError
from world_description.world_loading import (
    MAX_EXTENDS,
    MAX_WORLD_BYTES,
    MAX_WORLD_VALUES,
    load_world,
    world_data,
)
from world_description.world_schema import (
    GRAVITY_RANGE,
    MAX_JOINT_POSITION,
    MAX_SIZE_M,
    TURN_RAD,
    WORLD_EXTENT_M,
    CameraConfig,
    CellRoles,
    ControllerConfig,
    ConveyorConfig,
    DiffDriveConfig,
    DriveLimitsConfig,
    MaterialsConfig,
    MecanumConfig,
    ObstacleConfig,
    Pose,
    RobotConfig,
    SuctionConfig,
    Vec3,
    WorldConfig,
)
from world_description.world_sections import parse_world

__all__ = [
    'CameraConfig',
    'CellRoles',
    'ControllerConfig',
    'ConveyorConfig',
    'DiffDriveConfig',
    'DriveLimitsConfig',
    'GRAVITY_RANGE',
    'MAX_EXTENDS',
    'MAX_JOINT_POSITION',
    'MAX_SIZE_M',
    'MAX_WORLD_BYTES',
    'MAX_WORLD_VALUES',
    'MaterialsConfig',
    'MecanumConfig',
    'ObstacleConfig',
    'Pose',
    'RobotConfig',
    'SuctionConfig',
    'TURN_RAD',
    'Vec3',
    'WORLD_EXTENT_M',
    'WorldConfig',
    'WorldConfigError',
    'load_world',
    'parse_world',
    'world_data',
]
