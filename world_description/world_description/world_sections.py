"""The sections of a world (robots, drives, controllers, obstacles, the conveyor, materials and
their classes and rules, perturbations, cameras), each parsed and checked by the schema's
reader into its dataclass."""
from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Optional, Set, Tuple, Union

from world_description.conveyor_section import conveyor_section
from world_description.errors import WorldConfigError
from world_description.graph_names import graph_problem
from world_description.laser_section import laser_section
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
from world_description.ros_names import MAX_TOKEN_LENGTH, relative_problem, token_problem
from world_description.tool_section import suction_section
from world_description.world_schema import (
    GRAVITY_RANGE,
    LIFT_SWING_CLEARANCE_M,
    LINK_CLEARANCE_M,
    MAX_JOINT_POSITION,
    MAX_SIZE_M,
    TURN_RAD,
    WORLD_EXTENT_M,
    CameraConfig,
    CellRoles,
    ControllerConfig,
    DiffDriveConfig,
    DriveLimitsConfig,
    MaterialsConfig,
    MecanumConfig,
    ObstacleConfig,
    Pose,
    Reader,
    RobotConfig,
    WorldConfig,
)


def parse_world(data: Any, source: str = '<memory>') -> WorldConfig:
    r = Reader(source)
    if not isinstance(data, dict):
        raise WorldConfigError(f'{source}: the top level must be a mapping')
    r.only(data, 'world', {'gravity', 'floor_size', 'robots', 'obstacles', 'cameras',
                           'conveyor', 'materials', 'perturbations', 'cell'})
    robots = [_robot(r, item, i) for i, item in enumerate(r.list(data, 'robots', 'world'))]
    names = [rb.name for rb in robots]
    if len(set(names)) != len(names):
        raise WorldConfigError(f'{source}: robot names must be unique, got {names}')
    namespaces = [rb.namespace for rb in robots]
    if len(set(namespaces)) != len(namespaces):
        raise WorldConfigError(f'{source}: robot namespaces must be unique, got {namespaces}')
    prefixes = [rb.frame_prefix for rb in robots]
    if len(set(prefixes)) != len(prefixes):
        raise WorldConfigError(f'{source}: robot frame prefixes must be unique (each robot\'s '
                               f'frames are its own: frame_prefix: NAME/), got {prefixes}')
    cell = _cell(r, data['cell'], robots) if data.get('cell') is not None else None
    left_out = set(cell.left_out) if cell is not None else set()
    robots = [rb for rb in robots if rb.name not in left_out]
    obstacles = [_obstacle(r, item, i)
                 for i, item in enumerate(r.list(data, 'obstacles', 'world'))]
    cameras = [_camera(r, item, i, robots)
               for i, item in enumerate(r.list(data, 'cameras', 'world'))
               if not (isinstance(item, dict) and item.get('robot') in left_out)]
    conveyor = conveyor_section(r, data['conveyor']) if data.get('conveyor') is not None else None
    materials = None
    if data.get('materials') is not None:
        if conveyor is None:
            raise WorldConfigError(f'{source}: materials need a conveyor to be placed on')
        materials = _materials(r, data['materials'], obstacles)
    world = WorldConfig(source=source,
                        gravity=r.number(data, 'gravity', 'world', default=-9.81,
                                         lo=GRAVITY_RANGE[0], hi=GRAVITY_RANGE[1]),
                        floor_size=r.number(data, 'floor_size', 'world', default=4.0, lo=0.1,
                                            hi=2 * WORLD_EXTENT_M),
                        robots=robots, obstacles=obstacles, cameras=cameras,
                        conveyor=conveyor, materials=materials,
                        perturbations=_perturbations(r, data.get('perturbations') or {}),
                        cell=cell)
    problem = graph_problem(world)
    if problem:
        raise WorldConfigError(f'{source}: {problem}')
    return world


def _cell(r: Reader, item: Any, robots: List[RobotConfig]) -> CellRoles:
    """The cell's roles: the loader a fixed arm with a suction cup, each transport a mobile
    robot with a drive and a gripper, no robot in two roles."""
    where = 'cell'
    r.only(item, where, {'loader', 'transports', 'loading', 'clearance', 'trip_load',
                         'youbots', 'swing_clearance', 'link_clearance'})
    by_name = {rb.name: rb for rb in robots}
    loader = r.name(item, 'loader', where)
    arm = by_name.get(loader)
    if arm is None:
        raise r.fail(where, 'loader', f'{loader!r} is not a robot of this world '
                                      f'(robots: {sorted(by_name)})')
    if not arm.fixed_base or arm.suction is None:
        raise r.fail(where, 'loader', f'{loader!r} must be a fixed arm with a suction cup')
    names = item.get('transports')
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise r.fail(where, 'transports', f'must be a list of robot names, got {names!r}')
    for name in names:
        robot = by_name.get(name)
        if robot is None:
            raise r.fail(where, 'transports', f'{name!r} is not a robot of this world '
                                              f'(robots: {sorted(by_name)})')
        if robot.fixed_base or robot.drive is None or robot.suction is None:
            raise r.fail(where, 'transports', f'{name!r} must be a mobile robot with a drive '
                                              'and a gripper')
    if len(set(names)) != len(names) or loader in names:
        raise r.fail(where, 'transports', f'names each robot once, and not the loader: {names}')
    loading: Optional[Tuple[float, float, float]] = None
    if item.get('loading') is not None:
        r.only(item['loading'], where + '.loading', {'x', 'y', 'yaw'})
        x, y, yaw = (r.number(item['loading'], k, where + '.loading',
                              lo=-TURN_RAD if k == 'yaw' else -WORLD_EXTENT_M,
                              hi=TURN_RAD if k == 'yaw' else WORLD_EXTENT_M)
                     for k in ('x', 'y', 'yaw'))
        loading = (x, y, yaw)
    clearance = r.number(item, 'clearance', where, default=0.1, lo=0.0, hi=1.0)
    trip_load = int(r.number(item, 'trip_load', where, default=0, lo=0, hi=100, integer=True))
    # How many of them take part: the first ones (a sweep's fleet size); the others are left
    # out of the world.
    count = int(r.number(item, 'youbots', where, default=len(names), lo=1, hi=len(names),
                         integer=True))
    if count < len(names) and loading is None:
        raise r.fail(where, 'youbots', f'leaves out {names[count:]}: a fleet smaller than its '
                     'transports needs its loading pose (cell.loading)')
    swing = r.number(item, 'swing_clearance', where, default=LIFT_SWING_CLEARANCE_M, lo=0.0,
                     hi=0.2)
    links = r.number(item, 'link_clearance', where, default=LINK_CLEARANCE_M, lo=0.0, hi=0.2)
    return CellRoles(loader, tuple(names[:count]), loading, clearance, trip_load,
                     tuple(names[count:]), swing, links)


def _robot(r: Reader, item: Any, i: int) -> RobotConfig:
    where = f'robots[{i}]'
    r.only(item, where, {'name', 'urdf', 'namespace', 'pose', 'frame_prefix', 'drive',
                         'controllers', 'initial_joint_positions', 'fixed_base', 'suction',
                         'laser'})
    name = r.name(item, 'name', where)
    namespace = r.string(item, 'namespace', where, default=name).strip('/')
    problem = relative_problem(namespace) if namespace else ''
    if problem:
        raise r.fail(where, 'namespace', f'{namespace[:80]!r} {problem}')
    frame_prefix = r.string(item, 'frame_prefix', where, default='')
    if frame_prefix and not (len(frame_prefix) <= MAX_TOKEN_LENGTH
                             and re.fullmatch(r'[A-Za-z][A-Za-z0-9_]*(/[A-Za-z0-9_]+)*/?',
                                              frame_prefix)):
        raise r.fail(where, 'frame_prefix', f'{frame_prefix[:80]!r} must be a frame name\'s '
                     f'start of at most {MAX_TOKEN_LENGTH} characters (youbot/ or youbot_)')
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
        suction = suction_section(r, item['suction'], where + '.suction')
    laser = None
    if item.get('laser') is not None:
        if drive is None:
            raise r.fail(where, 'laser', 'a laser scanner is for a mobile base (one with a drive)')
        laser = laser_section(r, item['laser'], where + '.laser')
    return RobotConfig(name=name, urdf=r.string(item, 'urdf', where), namespace=namespace,
                       pose=pose, frame_prefix=frame_prefix,
                       drive=drive, limits=limits, controllers=controllers,
                       initial_joint_positions=initial_positions, fixed_base=fixed_base,
                       suction=suction, laser=laser)


def _drive(r: Reader, d: Any, dw: str
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


def _controller(r: Reader, c: Any, where: str) -> ControllerConfig:
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


def _obstacle(r: Reader, item: Any, i: int) -> ObstacleConfig:
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


def _materials(r: Reader, item: Any, obstacles: List[ObstacleConfig]) -> MaterialsConfig:
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


def _perturbations(r: Reader, item: Any) -> Perturbations:
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


def _paper_classes(r: Reader, item: Dict[str, Any], size: float, mass: float
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


def _classes(r: Reader, data: Any, size: float, mass: float) -> Tuple[MaterialClass, ...]:
    where = 'materials.classes'
    if not isinstance(data, dict) or not data:
        raise WorldConfigError(f'{r.source}: {where} must map each class name to its colour, '
                               'count, destination and route')
    rows = []
    for name, spec in data.items():
        at = f'{where}.{name}'
        if not isinstance(name, str) or token_problem(name):
            raise WorldConfigError(f'{r.source}: {where}: class name {str(name)[:80]!r} must '
                                   f'be a ROS name ([A-Za-z][A-Za-z0-9_]*) of at most '
                                   f'{MAX_TOKEN_LENGTH} characters')
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


def _with_hues(r: Reader, rows: List[Tuple[Any, ...]]) -> Tuple[MaterialClass, ...]:
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


def _check_rules(r: Reader, classes: Tuple[MaterialClass, ...],
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


def _camera(r: Reader, item: Any, i: int, robots: List[RobotConfig]) -> CameraConfig:
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
