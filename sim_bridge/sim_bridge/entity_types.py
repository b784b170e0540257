"""What the simulation interfaces say about an entity (no ROS): its category, info and state,
the filters a listing takes, a named pose, a spawnable resource, the error a request gets, and
the limits of what a request may ask for (docs/faults.md)."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import List, Optional, Tuple

import re2

from controllers.arrays import Vector
from sim_bridge.cell import MaterialBody

# simulation_interfaces/EntityCategory's values.
OBJECT, ROBOT, DYNAMIC_OBJECT, STATIC_OBJECT = 0, 1, 4, 5
WORLD_FRAME = 'world'
NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
NAMESPACE = re.compile(r'^/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$')
MATERIAL_NAME = re.compile(r'^material_\d+$')
MAX_SIZE_M = 5.0            # a spawned shape's largest dimension
MAX_MASS_KG = 1000.0
MAX_DISTANCE_M = 1000.0     # how far from the origin a pose may be
PENETRATION_M = 0.005       # a spawn that would sink deeper into a body is refused
# What a request may ask for (any client on the domain can send one; docs/faults.md): each is
# served in milliseconds within these.
MAX_LINEAR_SPEED_M_S = 50.0          # a state's (set or spawned) linear velocity
MAX_ANGULAR_SPEED_RAD_S = 50.0       # and angular velocity (PyBullet caps both at 100)
MAX_SPAWNED = 200                    # spawned entities alive at once
MAX_FILTER_CHARS = 1024              # a name filter (RE2: linear in the names it reads)
MAX_NAME_CHARS = 256                 # a name, a namespace, a tag
MAX_TAGS = 64                        # tags in a filter or an entity's info
MAX_DESCRIPTION_CHARS = 4096
MAX_URI_CHARS = 4096
RE2_OPTIONS = re2.Options()
RE2_OPTIONS.max_mem = 8 * 1024 * 1024       # a compiled filter's memory
RE2_OPTIONS.log_errors = False
SCRATCH_PREFIX = 'sim_node_urdf_'


class EntityError(Exception):
    """A request the entities cannot serve. ``code``: not_found, failed, unsupported,
    invalid_pose, name_not_unique, name_invalid, namespace_invalid, unsupported_format,
    no_resource, parse_error."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class State:
    """A pose and velocity in the world frame (quaternion x, y, z, w)."""
    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]
    linear: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular: Tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass
class Info:
    category: int
    description: str
    tags: List[str]


@dataclass
class Spawned:
    """A spawned body that is not a material: its spawn pose (a state reset puts it back),
    its half extents in its own frame where its shape is known, and its namespace."""
    body: int
    info: Info
    start: State
    half_extents: Optional[Tuple[float, float, float]] = None
    namespace: str = ''
    static: bool = False


@dataclass
class Entity:
    name: str
    body: int
    info: Info
    kind: str                                  # robot, material, scene, spawned
    robot: str = ''
    material: Optional[MaterialBody] = None
    spawned: Optional[Spawned] = None


@dataclass(frozen=True)
class Filters:
    """simulation_interfaces/EntityFilters: a regular expression on the name, categories (any),
    tags (any or all) and an overlap with a box or a sphere (world frame)."""
    pattern: str = ''
    categories: Tuple[int, ...] = ()
    tags: Tuple[str, ...] = ()
    all_tags: bool = False
    box: Optional[Tuple[Vector, Vector]] = None
    sphere: Optional[Tuple[Vector, float]] = None


@dataclass(frozen=True)
class NamedPose:
    name: str
    description: str
    tags: Tuple[str, ...]
    pose: State
    box: Optional[Tuple[Tuple[float, float, float], Tuple[float, float, float]]] = None


@dataclass(frozen=True)
class Spawnable:
    uri: str
    description: str
    half_extents: Optional[Tuple[float, float, float]] = None


def vec3(v: Vector) -> Tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def quat(q: Vector) -> Tuple[float, float, float, float]:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
