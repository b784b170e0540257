"""A world's robots checked against their own files before anything runs: each URDF a
``<robot>`` the simulator takes (world_description.urdf_check), with every joint and link the
world names (the drive's wheels, the controllers' joints, the initial positions, the suction
link), each initial position within its joint's limits, and each joint_limits file readable.

The simulator finds all of this when it loads the world; the trial runner, ``--rerun`` and the
storyboard check it first, so that a world from elsewhere (a result's copy, a bag's) is refused
in one line before any process starts."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

from world_description.joint_limits import JointLimitsError, load_acceleration_limits
from world_description.resources import resolve_resource
from world_description.urdf_check import (
    UrdfProblem,
    UrdfSummary,
    check_meshes,
    read_urdf_file,
    summarise_urdf,
)
from world_description.world_config import (
    DiffDriveConfig,
    MecanumConfig,
    RobotConfig,
    WorldConfig,
    WorldConfigError,
)


def check_robot_files(world: WorldConfig, base_dir: Optional[Path] = None) -> None:
    """WorldConfigError naming the robot and what is wrong; ``base_dir``: where the world's
    relative paths start (its file's directory)."""
    if base_dir is None and world.source and Path(world.source).is_file():
        base_dir = Path(world.source).parent
    for robot in world.robots:
        where = f'{world.source}: robot {robot.name}'
        try:
            path = resolve_resource(robot.urdf, base_dir)
            summary = summarise_urdf(read_urdf_file(path))
            check_meshes(summary, path.parent, resolve_resource)
        except UrdfProblem as exc:
            raise WorldConfigError(f'{where}: its URDF {robot.urdf}: {exc}') from None
        _check_names(robot, summary, where)
        for controller in robot.controllers:
            if controller.joint_limits is None:
                continue
            try:
                load_acceleration_limits(resolve_resource(controller.joint_limits, base_dir))
            except JointLimitsError as exc:
                raise WorldConfigError(f'{where}: {exc}') from None


def _check_names(robot: RobotConfig, urdf: UrdfSummary, where: str) -> None:
    named: List[str] = [j for c in robot.controllers for j in c.joints]
    if isinstance(robot.drive, DiffDriveConfig):
        named += [robot.drive.left_wheel_joint, robot.drive.right_wheel_joint]
    elif isinstance(robot.drive, MecanumConfig):
        named += list(robot.drive.wheel_joints)
    named += [j for j, _ in robot.initial_joint_positions]
    for name in named:
        joint = urdf.joint(name)
        if joint is None or joint.kind in ('fixed', ''):
            raise WorldConfigError(f'{where}: its URDF has no movable joint {name!r}')
    for name, position in robot.initial_joint_positions:
        joint = urdf.joint(name)
        assert joint is not None
        if joint.kind in ('revolute', 'prismatic') and not joint.lower <= position <= joint.upper:
            raise WorldConfigError(f'{where}: the initial position {position} of {name} is '
                                   f'outside its limits [{joint.lower}, {joint.upper}]')
    if robot.suction is not None and robot.suction.link not in urdf.link_names:
        raise WorldConfigError(f'{where}: its URDF has no link {robot.suction.link!r} for the '
                               'suction cup')
