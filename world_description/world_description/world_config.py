"""World description files: robots, obstacles and cameras, loaded from YAML and validated."""
from __future__ import annotations

import math
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Set, Tuple, Union

import yaml

from world_description.material_classes import (
    PAPER_RULES,
    ROUTES,
    MaterialClass,
    color_problem,
    hue_ranges,
)
from world_description.perturbations import (
    CameraPerturbation,
    MaterialPerturbation,
    Perturbations,
    RobotPerturbation,
    TimingPerturbation,
)

Vec3 = Tuple[float, float, float]


class WorldConfigError(ValueError):
    """A world file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class Pose:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0


@dataclass(frozen=True)
class DiffDriveConfig:
    left_wheel_joint: str
    right_wheel_joint: str
    wheel_radius: float
    wheel_separation: float
    # Stall torque of each wheel motor [N m]; also the velocity motor's force limit.
    wheel_effort: float


@dataclass(frozen=True)
class MecanumConfig:
    """Four Mecanum wheels driven as virtual omni-wheels (see robot_description's youBot)."""

    # Wheel joints in the order front-left, front-right, rear-right, rear-left.
    wheel_joints: Tuple[str, str, str, str]
    wheel_radius: float
    # k = lx + ly: half the wheelbase plus half the track (ros2_controllers' name).
    sum_of_robot_center_projection_on_X_Y_axis: float
    wheel_effort: float


@dataclass(frozen=True)
class DriveLimitsConfig:
    """Per-robot command limits; None falls back to the simulator's parameters (speeds) or
    means no limit (accelerations)."""

    max_speed: Optional[float] = None
    max_turn: Optional[float] = None
    # How fast the applied command may change, as diff_drive_controller's max_acceleration:
    # [m/s^2] for each of linear.x and linear.y, [rad/s^2] for angular.z.
    max_accel: Optional[float] = None
    max_turn_accel: Optional[float] = None


@dataclass(frozen=True)
class ControllerConfig:
    """A position-controlled joint group that follows trajectory_msgs/JointTrajectory."""

    name: str
    joints: Tuple[str, ...]
    # PyBullet position-motor gains (its constraint solver's kp and kd).
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    # Limits beyond the URDF's (acceleration), in MoveIt's joint_limits.yaml format: a path or
    # package:// URI, relative paths from the world file's directory. None: no limits.
    joint_limits: Optional[str] = None
    # JTC's constraints.<joint>.trajectory: how far a joint may lag its reference while a
    # trajectory runs [rad or m] before the trajectory is aborted and the group holds where it
    # is; 0 checks nothing (an action goal's own path tolerances replace it per joint).
    path_tolerance: float = 0.0


@dataclass(frozen=True)
class SuctionConfig:
    """A suction tool: grips the material whose face is within ``reach`` of ``link``'s origin."""

    link: str
    reach: float = 0.01
    max_payload: float = 12.0      # kg
    # The SetBool service that arms/releases it, relative to the robot's namespace; the
    # vacuum switch is published on <service>/holding and <service>/state.
    service: str = 'suction'


@dataclass(frozen=True)
class RobotConfig:
    name: str
    urdf: str
    namespace: str
    pose: Pose
    frame_prefix: str = ''
    drive: Optional[Union[DiffDriveConfig, MecanumConfig]] = None
    limits: DriveLimitsConfig = DriveLimitsConfig()
    controllers: Tuple[ControllerConfig, ...] = ()
    initial_joint_positions: Tuple[Tuple[str, float], ...] = ()
    fixed_base: bool = False
    suction: Optional[SuctionConfig] = None


@dataclass(frozen=True)
class CameraConfig:
    name: str
    width: int
    height: int
    rate: float
    vertical_fov_deg: float
    near: float
    far: float
    # Either mounted on a robot link (an optical frame: z forward, x right, y down) ...
    robot: Optional[str] = None
    link: Optional[str] = None
    # ... or fixed in the world, looking from position to look_at.
    position: Optional[Vec3] = None
    look_at: Optional[Vec3] = None
    frame_id: str = ''


@dataclass(frozen=True)
class ObstacleConfig:
    shape: str
    size: Tuple[float, ...]
    position: Vec3
    yaw: float = 0.0
    color: Tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)
    name: str = ''
    # False: drawn only (a marked area on the floor).
    collision: bool = True


@dataclass(frozen=True)
class ConveyorConfig:
    """A belt: a box whose top surface carries what lies on it along its x axis (at ``yaw``)."""

    position: Vec3                 # centre of the belt's top surface
    length: float
    width: float
    yaw: float = 0.0
    belt_speed: float = 0.05       # m/s along the belt's x axis
    # A wall across the belt's downstream end: what reaches it stays on the belt (accumulates)
    # while the belt runs on beneath it, instead of falling off.
    end_stop: bool = False


@dataclass(frozen=True)
class MaterialsConfig:
    """The material source: cubes of the cell's material classes dropped at the belt's start,
    and each class's rule (world_description.material_classes)."""

    classes: Tuple[MaterialClass, ...]
    size: float = 0.05                           # a class's edge unless it gives its own [m]
    mass: float = 0.1                            # [kg]
    gap: Tuple[float, float] = (0.25, 0.45)      # belt travel between two drops [m]
    lateral_jitter: float = 0.03                 # +- across the belt [m]
    start_offset: float = 0.1                    # from the belt's upstream end [m]
    seed: int = 0

    @property
    def counts(self) -> Tuple[Tuple[str, int], ...]:
        return tuple((c.name, c.count) for c in self.classes)

    @property
    def colors(self) -> Tuple[Tuple[str, Tuple[float, float, float, float]], ...]:
        return tuple((c.name, c.color) for c in self.classes)

    @property
    def total(self) -> int:
        return sum(c.count for c in self.classes)

    @property
    def largest(self) -> float:
        """The largest class's edge [m]."""
        return max((c.size for c in self.classes), default=self.size)

    def cls(self, name: str) -> MaterialClass:
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(name)


@dataclass(frozen=True)
class WorldConfig:
    source: str
    gravity: float = -9.81
    # Size of the visible floor patch [m]; the collision plane is infinite.
    floor_size: float = 4.0
    robots: List[RobotConfig] = field(default_factory=list)
    obstacles: List[ObstacleConfig] = field(default_factory=list)
    cameras: List[CameraConfig] = field(default_factory=list)
    conveyor: Optional[ConveyorConfig] = None
    materials: Optional[MaterialsConfig] = None
    # Realistic sources of failure, all off unless the world turns them on (perturbations.py).
    perturbations: Perturbations = field(default_factory=Perturbations)

    def robot(self, name: str) -> RobotConfig:
        for robot in self.robots:
            if robot.name == name:
                return robot
        raise KeyError(name)


_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')

# Every number of a world has a range: a world file, or the copy of one a result or a bag
# keeps, may come from elsewhere, and a value without one (gravity 1e300) runs a world that is
# no cell. The ranges hold every cell this simulator can run.
WORLD_EXTENT_M = 100.0            # each coordinate of what a world places [m]
GRAVITY_RANGE = (-30.0, 0.0)      # [m/s^2] along z: none to three g, downwards
TURN_RAD = 6.2832                 # a yaw within a turn either way (2 pi, rounded up) [rad]
MAX_JOINT_POSITION = 100.0        # an initial joint position [rad or m] (the robot's URDF
#                                   limits are checked by robot_files.py and the simulator)
MAX_SIZE_M = WORLD_EXTENT_M       # an obstacle's dimension


# A world file larger than this is refused before it is parsed: the worlds here are a few kB,
# and YAML is parsed at about 2 MB/s by each node that reads it (a 1 GB file took 8.5 min and
# 2.2 GB per node).
MAX_WORLD_BYTES = 4 * 1024 * 1024


# Values (numbers, strings, entries) of a world once YAML's aliases are expanded: the largest
# shipped world has about 300.
MAX_WORLD_VALUES = 100_000


# A world may extend another, which may extend another, this deep at most.
MAX_EXTENDS = 8


def load_world(path: str | Path) -> WorldConfig:
    """A world file, read and checked. One that ``extends`` another (a path relative to it, or
    ``package://``) is that world with its own keys merged in: a mapping key by key, any other
    value (a list too) replacing the base's; ``more_obstacles`` are added to the base's
    obstacles, and ``materials.classes`` replaces the base's ``counts`` and ``colors``."""
    path = Path(path)
    return parse_world(_resolved(path, _read(path), (path.resolve(),)), str(path))


def world_data(path: str | Path) -> Dict[str, Any]:
    """A world file as one mapping, the worlds it extends merged in (what ``load_world``
    parses): a world as it was, to run it again. Checked as load_world checks it."""
    path = Path(path)
    data = _resolved(path, _read(path), (path.resolve(),))
    parse_world(data, str(path))
    return _absolute_resources(dict(data), path.resolve().parent)


def _absolute_resources(data: Dict[str, Any], base_dir: Path) -> Dict[str, Any]:
    """``data`` with its robots' relative resource paths (a URDF, joint limits) made absolute
    from ``base_dir``, as the simulator resolves them: the mapping runs from anywhere."""
    def absolute(holder: Any, key: str) -> None:
        value = holder.get(key) if isinstance(holder, dict) else None
        if isinstance(value, str) and not value.startswith('package://'):
            rel = value[len('file://'):] if value.startswith('file://') else value
            if not Path(rel).is_absolute():
                holder[key] = str(base_dir / rel)
    for robot in data.get('robots') or []:
        absolute(robot, 'urdf')
        for controller in (robot.get('controllers') or [] if isinstance(robot, dict) else []):
            absolute(controller, 'joint_limits')
    return data


def _read(path: Path) -> Any:
    try:
        info = path.stat()
    except FileNotFoundError:
        raise WorldConfigError(f'world file {path} does not exist') from None
    except OSError as exc:          # (a symbolic link loop, a directory that cannot be read)
        raise WorldConfigError(f'world file {path}: {exc.strerror}') from None
    if stat.S_ISDIR(info.st_mode):
        raise WorldConfigError(f'world file {path} is a directory')
    if not stat.S_ISREG(info.st_mode):
        raise WorldConfigError(f'world file {path} is not a regular file')
    if info.st_size > MAX_WORLD_BYTES:
        raise WorldConfigError(f'world file {path} has {info.st_size} bytes; a world file is '
                               f'at most {MAX_WORLD_BYTES} bytes')
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
        _check_expanded_size(data, path)
        return data
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        what = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise WorldConfigError(f'{path}: not valid YAML{where}: {what}') from None
    except RecursionError:
        raise WorldConfigError(f'{path}: nested too deeply') from None
    except UnicodeDecodeError as exc:
        raise WorldConfigError(f'{path}: not UTF-8 text (byte {exc.start}: '
                               f'{exc.object[exc.start:exc.start + 1]!r})') from None
    except OSError as exc:
        raise WorldConfigError(f'{path}: cannot be read ({exc.strerror})') from None


def _check_expanded_size(data: Any, path: Path) -> None:
    """A world's values, counted as they expand: YAML's aliases let a few kilobytes stand for
    billions of values (the "billion laughs"), which every copy of the world (a result, a bag's
    record, a sweep's point) would write out."""
    count, stack = 0, [data]
    while stack:
        value = stack.pop()
        count += 1
        if count > MAX_WORLD_VALUES:
            raise WorldConfigError(f'{path}: more than {MAX_WORLD_VALUES} values once its YAML '
                                   'aliases are expanded')
        if isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)


def _resolved(path: Path, data: Any, seen: Tuple[Path, ...]) -> Any:
    """``data`` with the world it extends merged under it (see load_world)."""
    if not isinstance(data, dict) or 'extends' not in data:
        if isinstance(data, dict) and 'more_obstacles' in data:
            raise WorldConfigError(f'{path}: more_obstacles needs a world it extends')
        return data
    from world_description.resources import resolve_resource
    uri = data['extends']
    if not isinstance(uri, str) or not uri:
        raise WorldConfigError(f'{path}: extends must name a world file, got {uri!r}')
    base_path = resolve_resource(uri, path.parent)
    if base_path.resolve() in seen:
        raise WorldConfigError(f'{path}: extends {uri}, which extends it again')
    if len(seen) > MAX_EXTENDS:
        raise WorldConfigError(f'{path}: worlds extend each other more than {MAX_EXTENDS} deep')
    base = _resolved(base_path, _read(base_path), seen + (base_path.resolve(),))
    if not isinstance(base, dict):
        raise WorldConfigError(f'{base_path}: the top level must be a mapping')
    own = {k: v for k, v in data.items() if k not in ('extends', 'more_obstacles')}
    more = data.get('more_obstacles') or []
    if not isinstance(more, list):
        raise WorldConfigError(f'{path}: more_obstacles must be a list')
    merged = _merge(base, own)
    if isinstance(own.get('materials'), dict) and 'classes' in own['materials']:
        for key in ('counts', 'colors'):
            if key not in own['materials']:
                merged['materials'].pop(key, None)
    if more:
        obstacles = merged.get('obstacles') or []
        if not isinstance(obstacles, list):
            raise WorldConfigError(f'{path}: obstacles must be a list')
        merged['obstacles'] = list(obstacles) + more
    return merged


def _merge(base: Any, own: Any) -> Any:
    if isinstance(base, dict) and isinstance(own, dict):
        out = dict(base)
        for key, value in own.items():
            out[key] = _merge(base[key], value) if key in base else value
        return out
    return own


def parse_world(data: Any, source: str = '<memory>') -> WorldConfig:
    r = _Reader(source)
    if not isinstance(data, dict):
        raise WorldConfigError(f'{source}: the top level must be a mapping')
    r.only(data, 'world', {'gravity', 'floor_size', 'robots', 'obstacles', 'cameras',
                           'conveyor', 'materials', 'perturbations'})
    robots = [_robot(r, item, i) for i, item in enumerate(r.list(data, 'robots', 'world'))]
    names = [rb.name for rb in robots]
    if len(set(names)) != len(names):
        raise WorldConfigError(f'{source}: robot names must be unique, got {names}')
    namespaces = [rb.namespace for rb in robots]
    if len(set(namespaces)) != len(namespaces):
        raise WorldConfigError(f'{source}: robot namespaces must be unique, got {namespaces}')
    obstacles = [_obstacle(r, item, i)
                 for i, item in enumerate(r.list(data, 'obstacles', 'world'))]
    cameras = [_camera(r, item, i, robots)
               for i, item in enumerate(r.list(data, 'cameras', 'world'))]
    conveyor = _conveyor(r, data['conveyor']) if data.get('conveyor') is not None else None
    materials = None
    if data.get('materials') is not None:
        if conveyor is None:
            raise WorldConfigError(f'{source}: materials need a conveyor to be placed on')
        materials = _materials(r, data['materials'], obstacles)
    return WorldConfig(source=source,
                       gravity=r.number(data, 'gravity', 'world', default=-9.81,
                                        lo=GRAVITY_RANGE[0], hi=GRAVITY_RANGE[1]),
                       floor_size=r.number(data, 'floor_size', 'world', default=4.0, lo=0.1,
                                           hi=2 * WORLD_EXTENT_M),
                       robots=robots, obstacles=obstacles, cameras=cameras, conveyor=conveyor,
                       materials=materials,
                       perturbations=_perturbations(r, data.get('perturbations') or {}))


def _robot(r: '_Reader', item: Any, i: int) -> RobotConfig:
    where = f'robots[{i}]'
    r.only(item, where, {'name', 'urdf', 'namespace', 'pose', 'frame_prefix', 'drive',
                         'controllers', 'initial_joint_positions', 'fixed_base', 'suction'})
    name = r.name(item, 'name', where)
    namespace = r.string(item, 'namespace', where, default=name).strip('/')
    if namespace and not all(_NAME.match(part) for part in namespace.split('/')):
        raise WorldConfigError(f'{r.source}: {where}.namespace "{namespace}" is not a ROS name')
    pose_data = item.get('pose', {}) or {}
    r.only(pose_data, where + '.pose', {'x', 'y', 'z', 'yaw'})
    pose = Pose(*(r.number(pose_data, k, where + '.pose', default=0.0,
                           lo=-TURN_RAD if k == 'yaw' else -WORLD_EXTENT_M,
                           hi=TURN_RAD if k == 'yaw' else WORLD_EXTENT_M)
                  for k in ('x', 'y', 'z', 'yaw')))
    drive, limits = None, DriveLimitsConfig()
    if item.get('drive') is not None:
        drive, limits = _drive(r, item['drive'], where + '.drive')
    controllers = tuple(_controller(r, c, f'{where}.controllers[{k}]')
                        for k, c in enumerate(r.list(item, 'controllers', where)))
    names = [c.name for c in controllers]
    if len(set(names)) != len(names):
        raise WorldConfigError(f'{r.source}: {where}.controllers: names must be unique, '
                               f'got {names}')
    claimed = [j for c in controllers for j in c.joints]
    if isinstance(drive, MecanumConfig):
        claimed += list(drive.wheel_joints)
    elif drive is not None:
        claimed += [drive.left_wheel_joint, drive.right_wheel_joint]
    if len(set(claimed)) != len(claimed):
        raise WorldConfigError(f'{r.source}: {where}: a joint belongs to two controllers or '
                               f'to a controller and the drive: {claimed}')
    initial = item.get('initial_joint_positions') or {}
    if not isinstance(initial, dict):
        raise r.fail(where, 'initial_joint_positions', 'must be a mapping joint: position')
    initial_positions = tuple((str(j), r.number(initial, j, where + '.initial_joint_positions',
                                                lo=-MAX_JOINT_POSITION, hi=MAX_JOINT_POSITION))
                              for j in initial)
    fixed_base = item.get('fixed_base', False)
    if not isinstance(fixed_base, bool):
        raise r.fail(where, 'fixed_base', f'must be true or false, got {fixed_base!r}')
    if fixed_base and drive is not None:
        raise r.fail(where, 'drive', 'cannot drive a robot with a fixed base')
    suction = None
    if item.get('suction') is not None:
        sw = where + '.suction'
        r.only(item['suction'], sw, {'link', 'reach', 'max_payload', 'service'})
        suction = SuctionConfig(r.string(item['suction'], 'link', sw),
                                r.number(item['suction'], 'reach', sw, default=0.01, lo=1e-4,
                                         hi=0.1),
                                r.number(item['suction'], 'max_payload', sw, default=12.0,
                                         lo=1e-3, hi=1000.0),
                                r.string(item['suction'], 'service', sw, default='suction'))
        if not re.fullmatch(r'[a-z][a-z0-9_]*(/[a-z][a-z0-9_]*)*', suction.service):
            raise r.fail(sw, 'service', f'"{suction.service}" is not a relative ROS name')
    return RobotConfig(name=name, urdf=r.string(item, 'urdf', where), namespace=namespace,
                       pose=pose, frame_prefix=r.string(item, 'frame_prefix', where, default=''),
                       drive=drive, limits=limits, controllers=controllers,
                       initial_joint_positions=initial_positions, fixed_base=fixed_base,
                       suction=suction)


def _drive(r: '_Reader', d: Any, dw: str
           ) -> Tuple[Union[DiffDriveConfig, MecanumConfig], 'DriveLimitsConfig']:
    common = {'type', 'wheel_radius', 'wheel_effort', 'max_speed', 'max_turn', 'max_accel',
              'max_turn_accel'}
    kind = d.get('type') if isinstance(d, dict) else None
    if kind == 'diff_drive':
        r.only(d, dw, common | {'left_wheel_joint', 'right_wheel_joint', 'wheel_separation'})
        drive: Union[DiffDriveConfig, MecanumConfig] = DiffDriveConfig(
            left_wheel_joint=r.string(d, 'left_wheel_joint', dw),
            right_wheel_joint=r.string(d, 'right_wheel_joint', dw),
            wheel_radius=r.number(d, 'wheel_radius', dw, lo=1e-4, hi=5.0),
            wheel_separation=r.number(d, 'wheel_separation', dw, lo=1e-4, hi=20.0),
            wheel_effort=r.number(d, 'wheel_effort', dw, lo=1e-6, hi=1e5))
    elif kind == 'mecanum':
        k_name = 'sum_of_robot_center_projection_on_X_Y_axis'
        r.only(d, dw, common | {'wheel_joints', k_name})
        joints = d.get('wheel_joints')
        if (not isinstance(joints, list) or len(joints) != 4
                or not all(isinstance(j, str) for j in joints)):
            raise r.fail(dw, 'wheel_joints', 'must list 4 joint names: front-left, '
                         f'front-right, rear-right, rear-left; got {joints!r}')
        drive = MecanumConfig(
            wheel_joints=tuple(joints),
            wheel_radius=r.number(d, 'wheel_radius', dw, lo=1e-4, hi=5.0),
            sum_of_robot_center_projection_on_X_Y_axis=r.number(d, k_name, dw, lo=1e-4,
                                                                hi=20.0),
            wheel_effort=r.number(d, 'wheel_effort', dw, lo=1e-6, hi=1e5))
    else:
        raise WorldConfigError(f'{r.source}: {dw}.type must be "diff_drive" or "mecanum", '
                               f'got {kind!r}')
    def optional(key: str, hi: float) -> Optional[float]:
        return r.number(d, key, dw, lo=1e-3, hi=hi) if key in d else None
    limits = DriveLimitsConfig(max_speed=optional('max_speed', 10.0),
                               max_turn=optional('max_turn', 20.0),
                               max_accel=optional('max_accel', 100.0),
                               max_turn_accel=optional('max_turn_accel', 200.0))
    return drive, limits


def _controller(r: '_Reader', c: Any, where: str) -> ControllerConfig:
    r.only(c, where, {'name', 'joints', 'position_gain', 'velocity_gain', 'joint_limits',
                      'path_tolerance'})
    joints = c.get('joints')
    if (not isinstance(joints, list) or not joints
            or not all(isinstance(j, str) for j in joints)):
        raise r.fail(where, 'joints', f'must be a non-empty list of joint names, got {joints!r}')
    if len(set(joints)) != len(joints):
        raise r.fail(where, 'joints', f'has duplicates: {joints}')
    return ControllerConfig(
        name=r.name(c, 'name', where), joints=tuple(joints),
        position_gain=r.number(c, 'position_gain', where, default=0.3, lo=1e-4, hi=10.0),
        velocity_gain=r.number(c, 'velocity_gain', where, default=1.0, lo=0.0, hi=10.0),
        joint_limits=r.string(c, 'joint_limits', where) if 'joint_limits' in c else None,
        path_tolerance=r.number(c, 'path_tolerance', where, default=0.0, lo=0.0, hi=10.0))


def _obstacle(r: '_Reader', item: Any, i: int) -> ObstacleConfig:
    where = f'obstacles[{i}]'
    r.only(item, where, {'shape', 'size', 'position', 'yaw', 'color', 'name', 'collision'})
    shape = r.string(item, 'shape', where)
    sizes = {'box': 3, 'cylinder': 2, 'sphere': 1}
    if shape not in sizes:
        raise WorldConfigError(f'{r.source}: {where}.shape must be one of {sorted(sizes)}')
    size = r.vector(item, 'size', where, sizes[shape], lo=1e-4, hi=MAX_SIZE_M)
    color = r.rgba(item, 'color', where, default=(0.6, 0.6, 0.6, 1.0))
    collision = item.get('collision', True)
    if not isinstance(collision, bool):
        raise r.fail(where, 'collision', f'must be true or false, got {collision!r}')
    return ObstacleConfig(shape=shape, size=size, position=r.vec3(item, 'position', where),
                          yaw=r.number(item, 'yaw', where, default=0.0, lo=-TURN_RAD,
                                       hi=TURN_RAD), color=color,
                          name=r.string(item, 'name', where, default=''), collision=collision)


def _conveyor(r: '_Reader', item: Any) -> ConveyorConfig:
    where = 'conveyor'
    r.only(item, where, {'position', 'length', 'width', 'yaw', 'belt_speed', 'end_stop'})
    end_stop = item.get('end_stop', False)
    if not isinstance(end_stop, bool):
        raise r.fail(where, 'end_stop', f'must be true or false, got {end_stop!r}')
    return ConveyorConfig(position=r.vec3(item, 'position', where),
                          length=r.number(item, 'length', where, lo=0.1, hi=50.0),
                          width=r.number(item, 'width', where, lo=0.02, hi=5.0),
                          yaw=r.number(item, 'yaw', where, default=0.0, lo=-TURN_RAD,
                                       hi=TURN_RAD),
                          belt_speed=r.number(item, 'belt_speed', where, default=0.05, lo=0.0,
                                              hi=2.0), end_stop=end_stop)


def _materials(r: '_Reader', item: Any, obstacles: List[ObstacleConfig]) -> MaterialsConfig:
    where = 'materials'
    r.only(item, where, {'classes', 'counts', 'colors', 'size', 'mass', 'gap', 'lateral_jitter',
                         'start_offset', 'seed'})
    size = r.number(item, 'size', where, default=0.05, lo=0.005, hi=1.0)
    mass = r.number(item, 'mass', where, default=0.1, lo=1e-3, hi=100.0)
    if item.get('classes') is not None:
        if item.get('counts') is not None or item.get('colors') is not None:
            raise r.fail(where, 'classes', 'replaces counts and colors: give one or the other')
        classes = _classes(r, item['classes'], size, mass)
    else:
        classes = _paper_classes(r, item, size, mass)
    if sum(c.count for c in classes) == 0:
        raise r.fail(where, 'classes' if item.get('classes') is not None else 'counts',
                     'bring no material at all')
    _check_rules(r, classes, obstacles)
    largest = max(c.size for c in classes)
    lo_gap, hi_gap = r.vector(item, 'gap', where, 2, lo=0.0, hi=50.0, default=(0.25, 0.45))
    gap = (lo_gap, hi_gap)
    if gap[0] > gap[1]:
        raise r.fail(where, 'gap', f'must be [min, max], got {list(gap)}')
    if gap[0] < largest * 1.2:
        raise r.fail(where, 'gap', f'minimum {gap[0]} lets materials ({largest} m) touch')
    return MaterialsConfig(
        classes=classes, size=size, mass=mass, gap=gap,
        lateral_jitter=r.number(item, 'lateral_jitter', where, default=0.03, lo=0.0, hi=1.0),
        start_offset=r.number(item, 'start_offset', where, default=0.1, lo=0.0, hi=50.0),
        seed=int(r.number(item, 'seed', where, default=0, lo=0, hi=2**31 - 1, integer=True)))


def _perturbations(r: '_Reader', item: Any) -> Perturbations:
    """The ``perturbations`` section: each key off (0, or 1 for a scale) when not given."""
    r.only(item, 'perturbations', {'camera', 'materials', 'robots', 'timing'})

    def section(key: str, allowed: Set[str]) -> Dict[str, Any]:
        value = item.get(key) or {}
        r.only(value, f'perturbations.{key}', allowed)
        return dict(value)

    cam = section('camera', {'pixel_noise', 'brightness', 'white_balance', 'blur',
                             'position_error', 'angle_error'})
    where = 'perturbations.camera'
    camera = CameraPerturbation(
        pixel_noise=r.number(cam, 'pixel_noise', where, default=0.0, lo=0.0, hi=128.0),
        brightness=r.number(cam, 'brightness', where, default=0.0, lo=0.0, hi=0.5),
        white_balance=r.number(cam, 'white_balance', where, default=0.0, lo=0.0, hi=0.5),
        blur=r.number(cam, 'blur', where, default=0.0, lo=0.0, hi=20.0),
        position_error=r.number(cam, 'position_error', where, default=0.0, lo=0.0, hi=0.1),
        angle_error=r.number(cam, 'angle_error', where, default=0.0, lo=0.0, hi=10.0))
    mat = section('materials', {'mass_spread', 'size_spread', 'friction'})
    where = 'perturbations.materials'
    friction = None
    if mat.get('friction') is not None:
        lo, hi = r.vector(mat, 'friction', where, 2, lo=0.0, hi=5.0)
        if lo > hi:
            raise r.fail(where, 'friction', f'must be [min, max], got {[lo, hi]}')
        friction = (lo, hi)
    materials = MaterialPerturbation(
        mass_spread=r.number(mat, 'mass_spread', where, default=0.0, lo=0.0, hi=0.5),
        size_spread=r.number(mat, 'size_spread', where, default=0.0, lo=0.0, hi=0.3),
        friction=friction)
    rob = section('robots', {'joint_offset', 'velocity_scale', 'odometry_drift'})
    where = 'perturbations.robots'
    robots = RobotPerturbation(
        joint_offset=r.number(rob, 'joint_offset', where, default=0.0, lo=0.0, hi=0.2),
        velocity_scale=r.number(rob, 'velocity_scale', where, default=1.0, lo=0.1, hi=1.0),
        odometry_drift=r.number(rob, 'odometry_drift', where, default=0.0, lo=0.0, hi=0.3))
    tim = section('timing', {'belt_speed_drift', 'belt_drift_period'})
    where = 'perturbations.timing'
    timing = TimingPerturbation(
        belt_speed_drift=r.number(tim, 'belt_speed_drift', where, default=0.0, lo=0.0, hi=0.9),
        belt_drift_period=r.number(tim, 'belt_drift_period', where, default=30.0, lo=1.0,
                                   hi=3600.0))
    return Perturbations(camera, materials, robots, timing)


def _paper_classes(r: '_Reader', item: Dict[str, Any], size: float, mass: float
                   ) -> Tuple[MaterialClass, ...]:
    """The first form: ``counts`` and ``colors`` of the paper's colours, with its rules."""
    where = 'materials'
    counts, colors = item.get('counts'), item.get('colors')
    if not isinstance(counts, dict) or not counts:
        raise r.fail(where, 'counts', 'must map colour classes to how many, e.g. '
                                      '{purple: 1, orange: 6, blue: 1} (or give classes)')
    if not isinstance(colors, dict):
        raise r.fail(where, 'colors', 'must map each colour class to [r, g, b, a]')
    missing = sorted(set(counts) - set(colors))
    if missing:
        raise r.fail(where, 'colors', f'has no colour for {missing}')
    unruled = sorted(str(k) for k in counts if k not in PAPER_RULES)
    if unruled:
        raise r.fail(where, 'counts', f'{unruled}: only {sorted(PAPER_RULES)} have rules in '
                     'this form; give materials.classes with a destination and route each')
    rgba = {str(k): r.rgba(colors, k, where + '.colors') for k in colors}
    return _with_hues(r, [
        (str(k), rgba[str(k)], int(r.number(counts, k, where + '.counts', lo=0, hi=1000,
                                            integer=True)), *PAPER_RULES[str(k)], size, mass,
         None) for k in counts])


def _classes(r: '_Reader', data: Any, size: float, mass: float) -> Tuple[MaterialClass, ...]:
    where = 'materials.classes'
    if not isinstance(data, dict) or not data:
        raise WorldConfigError(f'{r.source}: {where} must map each class name to its colour, '
                               'count, destination and route')
    rows = []
    for name, spec in data.items():
        at = f'{where}.{name}'
        if not isinstance(name, str) or not _NAME.match(name):
            raise WorldConfigError(f'{r.source}: {where}: class name {name!r} must be a ROS '
                                   'name ([A-Za-z][A-Za-z0-9_]*)')
        r.only(spec, at, {'color', 'count', 'destination', 'route', 'size', 'mass', 'hue'})
        route = r.string(spec, 'route', at)
        if route not in ROUTES:
            raise r.fail(at, 'route', f'must be one of {list(ROUTES)} (place: set down by the '
                         f'Zu 12; carry: loaded onto the youBot), got {route!r}')
        hue = None
        if spec.get('hue') is not None:
            lo, hi = r.vector(spec, 'hue', at, 2, lo=0.0, hi=180.0)
            hue = (int(lo), int(hi))
        rows.append((name, r.rgba(spec, 'color', at),
                     int(r.number(spec, 'count', at, lo=0, hi=1000, integer=True)),
                     r.string(spec, 'destination', at), route,
                     r.number(spec, 'size', at, default=size, lo=0.005, hi=1.0),
                     r.number(spec, 'mass', at, default=mass, lo=1e-3, hi=100.0), hue))
    return _with_hues(r, rows)


def _with_hues(r: '_Reader', rows: List[Tuple[Any, ...]]) -> Tuple[MaterialClass, ...]:
    """The classes, each with the hue range the camera finds it by; refused when the camera
    could not tell one from the belt or from another."""
    for name, color, *_ in rows:
        problem = color_problem(name, color)
        if problem:
            raise WorldConfigError(f'{r.source}: materials: {problem}')
    try:
        ranges = hue_ranges({row[0]: row[1] for row in rows},
                            {row[0]: row[7] for row in rows if row[7] is not None})
    except ValueError as exc:
        raise WorldConfigError(f'{r.source}: materials: {exc}') from None
    return tuple(MaterialClass(name, color, count, dest, route, size, mass, ranges[name])
                 for name, color, count, dest, route, size, mass, _ in rows)


def _check_rules(r: '_Reader', classes: Tuple[MaterialClass, ...],
                 obstacles: List[ObstacleConfig]) -> None:
    """Each class's destination is a region of the world a material fits on."""
    named = {o.name: o for o in obstacles if o.name}
    for c in classes:
        o = named.get(c.destination)
        if o is None:
            raise WorldConfigError(
                f'{r.source}: materials: {c.name} goes to {c.destination!r}, which is no '
                f'obstacle of this world (named ones: {sorted(named)})')
        if o.shape != 'box':
            raise WorldConfigError(f'{r.source}: materials: {c.name} goes to {c.destination}, '
                                   f'a {o.shape}: a destination is a box (its top face)')
        if min(o.size[0], o.size[1]) < c.size:
            raise WorldConfigError(
                f'{r.source}: materials: {c.name} ({c.size} m) does not fit on '
                f'{c.destination} ({o.size[0]} x {o.size[1]} m)')


def _camera(r: '_Reader', item: Any, i: int, robots: List[RobotConfig]) -> CameraConfig:
    where = f'cameras[{i}]'
    r.only(item, where, {'name', 'robot', 'link', 'position', 'look_at', 'width', 'height',
                         'rate', 'vertical_fov_deg', 'near', 'far', 'frame_id'})
    name = r.name(item, 'name', where)
    robot = item.get('robot')
    width = int(r.number(item, 'width', where, default=320, lo=8, hi=4096, integer=True))
    height = int(r.number(item, 'height', where, default=240, lo=8, hi=4096, integer=True))
    rate = r.number(item, 'rate', where, default=15.0, lo=1e-3, hi=1000.0)
    fov = r.number(item, 'vertical_fov_deg', where, default=60.0, lo=1.0, hi=170.0)
    near = r.number(item, 'near', where, default=0.01, lo=1e-5, hi=100.0)
    far = r.number(item, 'far', where, default=10.0, lo=1e-3, hi=1000.0)
    if far <= near:
        raise WorldConfigError(f'{r.source}: {where}: far must be greater than near')
    if robot is not None:
        if robot not in {rb.name for rb in robots}:
            raise WorldConfigError(f'{r.source}: {where}.robot "{robot}" is not a robot of '
                                   'this world')
        link = r.string(item, 'link', where)
        prefix = next(rb.frame_prefix for rb in robots if rb.name == robot)
        return CameraConfig(name=name, width=width, height=height, rate=rate,
                            vertical_fov_deg=fov, near=near, far=far, robot=robot, link=link,
                            frame_id=r.string(item, 'frame_id', where, default=prefix + link))
    position = r.vec3(item, 'position', where)
    look_at = r.vec3(item, 'look_at', where)
    if math.dist(position, look_at) < 1e-6:
        raise WorldConfigError(f'{r.source}: {where}: position and look_at coincide')
    return CameraConfig(name=name, width=width, height=height, rate=rate,
                        vertical_fov_deg=fov, near=near, far=far, position=position,
                        look_at=look_at, frame_id=r.string(item, 'frame_id', where,
                                                           default=name + '_optical_frame'))


class _Reader:
    """Typed field access that raises WorldConfigError naming file and field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, key: str, what: str) -> WorldConfigError:
        return WorldConfigError(f'{self.source}: {where}.{key} {what}')

    def only(self, data: Any, where: str, allowed: Set[str]) -> None:
        if not isinstance(data, dict):
            raise WorldConfigError(f'{self.source}: {where} must be a mapping')
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise WorldConfigError(f'{self.source}: {where}: unknown keys {unknown}; '
                                   f'allowed: {sorted(allowed)}')

    def list(self, data: Dict[str, Any], key: str, where: str) -> List[Any]:
        value = data.get(key, []) or []
        if not isinstance(value, list):
            raise self.fail(where, key, 'must be a list')
        return value

    def string(self, data: Dict[str, Any], key: str, where: str,
               default: Optional[str] = None) -> str:
        value = data.get(key, default)
        if value is None:
            raise self.fail(where, key, 'is required')
        if not isinstance(value, str):
            raise self.fail(where, key, f'must be a string, got {value!r}')
        return value

    def name(self, data: Dict[str, Any], key: str, where: str) -> str:
        value = self.string(data, key, where)
        if not _NAME.match(value):
            raise self.fail(where, key, f'"{value}" must be a ROS name ([A-Za-z][A-Za-z0-9_]*)')
        return value

    def number(self, data: Dict[str, Any], key: str, where: str, *, lo: float, hi: float,
               default: Optional[float] = None, integer: bool = False) -> float:
        """A number within [lo, hi] (every number of a world has a range)."""
        value = data.get(key, default)
        if value is None:
            raise self.fail(where, key, 'is required')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, key, f'must be a number, got {value!r}')
        if integer and math.isfinite(value) and int(value) != value:
            raise self.fail(where, key, f'must be an integer, got {value}')
        if not math.isfinite(value) or not (lo <= value <= hi):
            raise self.fail(where, key, f'must be finite and within [{lo}, {hi}], got {value}')
        return float(value)

    def vector(self, data: Dict[str, Any], key: str, where: str, n: int, *, lo: float,
               hi: float, default: Optional[Tuple[float, ...]] = None) -> Tuple[float, ...]:
        value = data.get(key, default)
        if value is None:
            raise self.fail(where, key, 'is required')
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise self.fail(where, key, f'must be a list of {n} numbers, got {value!r}')
        tmp = {str(i): v for i, v in enumerate(value)}
        return tuple(self.number(tmp, str(i), f'{where}.{key}', lo=lo, hi=hi) for i in range(n))

    def vec3(self, data: Dict[str, Any], key: str, where: str) -> Tuple[float, float, float]:
        x, y, z = self.vector(data, key, where, 3, lo=-WORLD_EXTENT_M, hi=WORLD_EXTENT_M)
        return (x, y, z)

    def rgba(self, data: Dict[str, Any], key: str, where: str,
             default: Optional[Tuple[float, ...]] = None
             ) -> Tuple[float, float, float, float]:
        r, g, b, a = self.vector(data, key, where, 4, lo=0.0, hi=1.0, default=default)
        return (r, g, b, a)
