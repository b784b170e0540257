"""The schema of a world file: what each section holds (frozen dataclasses), the range of every
number, and the reader that checks each field as it is read (``Reader``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Set, Tuple, Union

from world_description.errors import WorldConfigError
from world_description.material_classes import MaterialClass
from world_description.perturbations import Perturbations
from world_description.ros_names import token_problem

Vec3 = Tuple[float, float, float]


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
    """A suction tool: grips the material whose face is within ``reach`` of its point (``link``'s
    origin, moved by ``offset`` in the link's frame). An arm's tool: the chain from the robot's
    base to it is the arm the coordinator plans for."""

    link: str
    reach: float = 0.01
    max_payload: float = 12.0      # kg
    # The SetBool service that arms/releases it, relative to the robot's namespace; the
    # vacuum switch is published on <service>/holding and <service>/state.
    service: str = 'suction'
    # The tool's point in ``link``'s frame [m] (a cup at the flange: its length along z), and
    # whether the tool may turn freely about its z axis (a round cup: the arm's IK leaves its
    # rotation about the axis free).
    offset: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    free_yaw: bool = False


@dataclass(frozen=True)
class LaserConfig:
    """A planar laser scanner on a mobile base: its mount in base_link (x, y, z [m], yaw
    [rad]), its field of view [rad] centred on the mount's x axis, the number of rays over it,
    the ranges it reports [m], its scans a second and the standard deviation of each range [m].
    By default a 270 degree scanner as mobile manipulators carry at a front corner (Hokuyo's
    UST-10LX: 10 m, 0.25 degree steps, 40 Hz), read at 1 degree steps to 4 m, 10 times a
    second. Published as sensor_msgs/LaserScan on
    ``<namespace>/scan`` in frame ``<frame_prefix>laser``; a ray that hits nothing reads +inf
    (REP 117)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    fov: float = 4.71238898        # 270 degrees
    rays: int = 271
    range_min: float = 0.02
    range_max: float = 4.0
    rate: float = 10.0
    noise: float = 0.01


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
    laser: Optional[LaserConfig] = None


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
class BeltEncoderConfig:
    """The conveyor drive's encoder, as a real drive reports it: the belt's travel in whole
    counts, and its speed, read over each period with its noise; published at its own rate on
    ``/conveyor/joint_states`` (joint ``belt``: position [m], velocity [m/s])."""

    resolution: float = 1.0e-4     # belt travel per count [m]
    noise: float = 0.0             # standard deviation of the speed reading [m/s]
    # Readings a second: a drive's status as a fieldbus polls it (at the robots' 30 Hz states,
    # its messages cost the run 5 % more CPU for nothing the cell used).
    rate: float = 10.0


# A belt's end stop (ConveyorConfig.end_stop): a wall across the belt's end, this thick along
# the belt and this high above its top [m] (a little higher than the materials it holds).
END_STOP_THICKNESS_M = 0.02
END_STOP_HEIGHT_M = 0.06
# What the loader's cup holds keeps this far from what is on the belt or at its end as it
# swings on from a lift point, by default [m] (CellRoles.swing_clearance): its planned way
# must not touch them.
LIFT_SWING_CLEARANCE_M = 0.0
# The loader's links keep this far from the conveyor and the world's boxes on those swings, by
# default [m] (CellRoles.link_clearance; cell_layout/link_clearance.py).
LINK_CLEARANCE_M = 0.0


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
    # What the cell is told of the belt's motion by its drive (None: nothing; the cell then
    # senses the belt's speed from its camera's tracks only).
    encoder: Optional[BeltEncoderConfig] = None


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
class CellRoles:
    """What each robot does in a pipeline cell (the world's ``cell`` section): the arm that
    picks from the belt, and the mobile robots that carry. A world without the section has
    the paper's: ``zu12`` loads and ``youbot`` carries. With several transports: where the
    loader loads them (``loading``: x, y, yaw; one at a time; each waits for it at its start
    pose), how near two bases may come (``clearance``, between their footprints [m]), and how
    many materials a transport sets off with at most (``trip_load``; 0: a full plate).
    ``youbots``: how many of the transports take part, the first ones (default all); the
    others (``left_out``) are left out of the world, and the cameras they carry with them.
    ``swing_clearance``: how far what the loader's cup holds keeps from the materials on the
    belt and its end stop as it swings on from a lift point [m] (default 0: its planned way
    does not touch them; more for an arm that follows its plans less closely).
    ``link_clearance``: how far the loader's links keep from the conveyor and the world's boxes
    on those swings [m] (default 0: they do not touch them)."""
    loader: str = 'zu12'
    transports: Tuple[str, ...] = ('youbot',)
    loading: Optional[Tuple[float, float, float]] = None    # None: the first transport's start
    clearance: float = 0.1
    trip_load: int = 0
    left_out: Tuple[str, ...] = ()
    swing_clearance: float = LIFT_SWING_CLEARANCE_M
    link_clearance: float = LINK_CLEARANCE_M


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
    cell: Optional[CellRoles] = None    # as the world names them (None: the paper's)

    @property
    def roles(self) -> CellRoles:
        """The cell's roles: the world's, or the paper's."""
        return self.cell or CellRoles()

    def robot(self, name: str) -> RobotConfig:
        for robot in self.robots:
            if robot.name == name:
                return robot
        raise KeyError(name)



# Every number of a world has a range: a world file, or the copy of one a result or a bag
# keeps, may come from elsewhere, and a value without one (gravity 1e300) runs a world that is
# no cell. The ranges hold every cell this simulator can run.
WORLD_EXTENT_M = 100.0            # each coordinate of what a world places [m]
GRAVITY_RANGE = (-30.0, 0.0)      # [m/s^2] along z: none to three g, downwards
TURN_RAD = 6.2832                 # a yaw within a turn either way (2 pi, rounded up) [rad]
MAX_JOINT_POSITION = 100.0        # an initial joint position [rad or m] (the robot's URDF
#                                   limits are checked by robot_files.py and the simulator)
MAX_SIZE_M = WORLD_EXTENT_M       # an obstacle's dimension


class Reader:
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
        problem = token_problem(value)
        if problem:
            raise self.fail(where, key, f'{value[:80]!r} {problem}')
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
