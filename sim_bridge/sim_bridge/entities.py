"""The world's entities as the simulation interfaces (``simulation_interfaces``) see them: what
they are, where they are, and how they are spawned, moved and deleted. No ROS here: the node's
adapter (``sim_api.py``) turns requests into these calls and the errors into result codes.

Entities, by name:
- the robots (their world file names): category ROBOT; their state is base_link's;
- the cell's materials, ``material_<index>`` (the index is the ground truth's order of
  appearance) or the name a spawned one was given: category OBJECT, tagged ``material`` and
  their class;
- the world's fixed scene: ``floor``, ``conveyor`` (and ``conveyor_end_stop``,
  ``conveyor_stand``), each obstacle by its name (``obstacle_<k>`` if it has none): category
  STATIC_OBJECT;
- what was spawned: a material of the world's classes (``material://<class>``), a box,
  cylinder or sphere (``shape://box?size=x,y,z&mass=m&color=r,g,b``), or a URDF
  (``package://``, ``file://`` or a path, or the URDF text itself).

A state is the entity's canonical frame (a URDF's root link frame, a shape's centre) in the
world frame, with its velocity in the world frame.
"""
from __future__ import annotations

import math
import os
import re
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple
from urllib.parse import parse_qs, unquote, urlparse

import numpy as np
import pybullet
import re2

from controllers.arrays import Vector
from sim_bridge.cell import MaterialBody
from sim_bridge.scratch import ScratchDir
from sim_bridge.world import URDF_FLAGS, SimWorld
from world_description.resources import resolve_resource
from world_description.urdf_check import (
    UrdfProblem,
    check_meshes,
    read_urdf_file,
    summarise_urdf,
)
from world_description.world_config import ObstacleConfig

# simulation_interfaces/EntityCategory's values.
OBJECT, ROBOT, DYNAMIC_OBJECT, STATIC_OBJECT = 0, 1, 4, 5
WORLD_FRAME = 'world'
_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
_NAMESPACE = re.compile(r'^/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$')
_MATERIAL_NAME = re.compile(r'^material_\d+$')
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
_RE2_OPTIONS = re2.Options()
_RE2_OPTIONS.max_mem = 8 * 1024 * 1024       # a compiled filter's memory
_RE2_OPTIONS.log_errors = False
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
class _Spawned:
    """A spawned body that is not a material: its spawn pose (a state reset puts it back),
    its half extents in its own frame where its shape is known, and its namespace."""
    body: int
    info: Info
    start: State
    half_extents: Optional[Tuple[float, float, float]] = None
    namespace: str = ''
    static: bool = False


@dataclass
class _Entity:
    name: str
    body: int
    info: Info
    kind: str                                  # robot, material, scene, spawned
    robot: str = ''
    material: Optional[MaterialBody] = None
    spawned: Optional[_Spawned] = None


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


class Entities:
    """The entities of ``world``; ``now`` gives the simulated time [s] for a spawned
    material's record."""

    def __init__(self, world: SimWorld, now: Callable[[], float]) -> None:
        self._world, self._p, self._now = world, world.client, now
        self._spawned: Dict[str, _Spawned] = {}
        self._info: Dict[str, Info] = {}           # set by SetEntityInfo
        # Where a URDF sent as text is written for PyBullet to read, for as long as that takes.
        self._scratch = ScratchDir(SCRATCH_PREFIX)

    # --- what there is ------------------------------------------------------------------------
    def _all(self) -> List[_Entity]:
        w = self._world
        out = [_Entity(name, robot.body, Info(ROBOT, f'robot {name} ({Path(robot.urdf).name})',
                                              self._robot_tags(name)), 'robot', robot=name)
               for name, robot in w.robots.items()]
        for m in w.materials:
            out.append(_Entity(m.name or f'material_{m.index}', m.body, Info(
                OBJECT, f'a {m.color} material, {m.size * 1000:.0f} mm, {m.mass:g} kg',
                ['material', m.color] + (['spawned'] if m.name else [])), 'material',
                material=m))
        for name, body, what in self._scene():
            out.append(_Entity(name, body, Info(STATIC_OBJECT, what, ['scene']), 'scene'))
        out += [_Entity(name, s.body, s.info, 'spawned', spawned=s)
                for name, s in self._spawned.items()]
        for e in out:
            if e.name in self._info:
                e.info = self._info[e.name]
        return out

    def _scene(self) -> List[Tuple[str, int, str]]:
        w = self._world
        scene = [('floor', w.floor, 'the floor')]
        if w.conveyor is not None:
            scene.append(('conveyor', w.conveyor.body, 'the conveyor belt'))
            for name, body in (('conveyor_end_stop', w.conveyor.stop_body),
                               ('conveyor_stand', w.conveyor.stand_body)):
                if body is not None:
                    scene.append((name, body, name.replace('_', ' ')))
        for k, (body, obstacle) in enumerate(w.obstacles.items()):
            scene.append((obstacle.name or f'obstacle_{k}', body,
                          f'a {obstacle.shape} of the world' + (
                              '' if obstacle.collision else ' (drawn only)')))
        return scene

    def _robot_tags(self, name: str) -> List[str]:
        robot = self._world.robots[name]
        tags = ['robot', 'fixed_base' if robot.config.fixed_base else 'mobile']
        if robot.drive is not None:
            tags.append('mecanum' if robot.config.drive.__class__.__name__ == 'MecanumConfig'
                        else 'differential')
        if robot.controllers:
            tags.append('arm')
        return tags

    def _get(self, name: str) -> _Entity:
        for e in self._all():
            if e.name == name:
                return e
        raise EntityError('not_found', f'no entity named {name!r}')

    def names(self, filters: Filters = Filters()) -> List[str]:
        pattern = _filter_pattern(filters.pattern)
        _check_tags(filters.tags, 'the tags filter')
        out = []
        for e in self._all():
            if pattern is not None and not pattern.search(e.name):
                continue
            if filters.categories and e.info.category not in filters.categories:
                continue
            if filters.tags:
                have = [t in e.info.tags for t in filters.tags]
                if not (all(have) if filters.all_tags else any(have)):
                    continue
            if not self._overlaps(e.body, filters):
                continue
            out.append(e.name)
        return out

    def _overlaps(self, body: int, filters: Filters) -> bool:
        if filters.box is None and filters.sphere is None:
            return True
        lo, hi = self._world_aabb(body)
        if filters.box is not None:
            a, b = (np.asarray(c, float) for c in filters.box)
            blo, bhi = np.minimum(a, b), np.maximum(a, b)
            return bool(np.all(lo <= bhi) and np.all(blo <= hi))
        assert filters.sphere is not None
        centre, radius = np.asarray(filters.sphere[0], float), filters.sphere[1]
        nearest = np.clip(centre, lo, hi)
        return float(np.linalg.norm(nearest - centre)) <= radius

    def _world_aabb(self, body: int) -> Tuple[np.ndarray, np.ndarray]:
        boxes = [self._p.getAABB(body, link) for link in range(-1, self._p.getNumJoints(body))]
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        return lo, hi

    def info(self, name: str) -> Info:
        return self._get(name).info

    def set_info(self, name: str, info: Info) -> None:
        self._get(name)
        if info.category not in (OBJECT, ROBOT, 2, DYNAMIC_OBJECT, STATIC_OBJECT):
            raise EntityError('failed', f'category {info.category} is none of EntityCategory')
        if len(info.description) > MAX_DESCRIPTION_CHARS:
            raise EntityError('failed', f'the description has {len(info.description)} '
                              f'characters (at most {MAX_DESCRIPTION_CHARS})')
        _check_tags(info.tags, 'the tags')
        self._info[name] = replace(info, tags=list(info.tags))

    # --- state --------------------------------------------------------------------------------
    def state(self, name: str) -> State:
        e = self._get(name)
        pos: Sequence[float]
        orn: Sequence[float]
        if e.kind == 'robot':
            pos, orn = self._world.robots[e.robot].base_link_world()
        else:
            pos, orn = self._frame_pose(e.body)
        com, _ = self._p.getBasePositionAndOrientation(e.body)
        v_com, omega = self._p.getBaseVelocity(e.body)
        # (The frame's origin moves as the body turns about its centre of mass.)
        v = np.asarray(v_com) + np.cross(omega, np.subtract(pos, com))
        return State(_vec3(pos), _quat(orn), _vec3(v), _vec3(omega))

    def _frame_pose(self, body: int) -> Tuple[Sequence[float], Sequence[float]]:
        """The base's link frame (PyBullet reports its centre of mass)."""
        com_pos, com_orn = self._p.getBasePositionAndOrientation(body)
        info = self._p.getDynamicsInfo(body, -1)
        inv = self._p.invertTransform(info[3], info[4])
        pos, orn = self._p.multiplyTransforms(com_pos, com_orn, inv[0], inv[1])
        return _vec3(pos), _quat(orn)

    def set_state(self, name: str, state: State, frame: str = '') -> None:
        e = self._get(name)
        state = self._in_world(state, frame)
        moving = any(v != 0.0 for v in state.linear + state.angular)
        if e.kind == 'scene':
            raise EntityError('failed', f'{name} is part of the world\'s fixed scene (the '
                              'cameras draw it once): it cannot be moved')
        if e.kind == 'robot':
            robot = self._world.robots[e.robot]
            if robot.config.fixed_base:
                raise EntityError('failed', f'{name} is fixed to the world (its TF and its '
                                  'planners assume its base pose): it cannot be moved')
        if e.spawned is not None and e.spawned.static and moving:
            raise EntityError('failed', f'{name} is static (mass 0): it takes a pose, not a '
                              'velocity')
        if e.material is not None:
            holder = self._holder(e.material)
            if holder:
                raise EntityError('failed', f'{name} is held by {holder}: release it first')
        self._place(e.body, state)

    def _place(self, body: int, state: State) -> None:
        info = self._p.getDynamicsInfo(body, -1)
        com = self._p.multiplyTransforms(state.position, state.orientation, info[3], info[4])
        self._p.resetBasePositionAndOrientation(body, com[0], com[1])
        # (The velocity asked for is the frame origin's; PyBullet's, the centre of mass's.)
        lever = np.subtract(com[0], state.position)
        v = np.asarray(state.linear) + np.cross(state.angular, lever)
        self._p.resetBaseVelocity(body, _vec3(v), state.angular)

    def _holder(self, material: MaterialBody) -> str:
        for robot, suction in self._world.suctions.items():
            if suction.held is material:
                return f"{robot}'s {suction.link}"
        return ''

    def _in_world(self, state: State, frame: str) -> State:
        """``state`` checked, and given in the world frame (``frame``: '', 'world' or an
        entity's name)."""
        pos, orn = np.asarray(state.position, float), np.asarray(state.orientation, float)
        values = np.concatenate([pos, orn, state.linear, state.angular])
        if not np.all(np.isfinite(values)):
            raise EntityError('invalid_pose', 'the state has values that are not finite')
        speed, spin = math.hypot(*state.linear), math.hypot(*state.angular)
        if speed > MAX_LINEAR_SPEED_M_S or spin > MAX_ANGULAR_SPEED_RAD_S:
            raise EntityError('invalid_pose', f'the velocity ({speed:.4g} m/s, {spin:.4g} '
                              f'rad/s) is beyond {MAX_LINEAR_SPEED_M_S:g} m/s or '
                              f'{MAX_ANGULAR_SPEED_RAD_S:g} rad/s')
        norm = float(np.linalg.norm(orn))
        if abs(norm - 1.0) > 1e-3:
            raise EntityError('invalid_pose', f'the orientation is not a unit quaternion '
                              f'(norm {norm:.4f})')
        if frame not in ('', WORLD_FRAME):
            ref = self.state(frame) if frame in self.names() else None
            if ref is None:
                raise EntityError('invalid_pose', f'frame {frame!r} is neither "world" nor an '
                                  'entity')
            p, q = self._p.multiplyTransforms(ref.position, ref.orientation, pos.tolist(),
                                              orn.tolist())
            rot = np.array(self._p.getMatrixFromQuaternion(ref.orientation)).reshape(3, 3)
            state = State(_vec3(p), _quat(q), _vec3(rot @ state.linear),
                          _vec3(rot @ state.angular))
            pos, orn = np.asarray(state.position), np.asarray(state.orientation)
        if float(np.linalg.norm(pos)) > MAX_DISTANCE_M:
            raise EntityError('invalid_pose', f'the position is more than {MAX_DISTANCE_M:g} m '
                              'from the origin')
        return replace(state, orientation=_quat(orn / norm))

    def bounds(self, name: str) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """An axis-aligned box in the entity's own frame that holds it (lower, upper)."""
        e = self._get(name)
        half = (e.spawned.half_extents if e.spawned is not None else
                (e.material.size / 2,) * 3 if e.material is not None else None)
        if half is not None:
            return (-half[0], -half[1], -half[2]), half
        s = self.state(name)
        rot = np.array(self._p.getMatrixFromQuaternion(s.orientation)).reshape(3, 3)
        corners = []
        for link in range(-1, self._p.getNumJoints(e.body)):
            lo, hi = self._p.getAABB(e.body, link)
            corners += [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]
        local = (np.asarray(corners) - np.asarray(s.position)) @ rot
        return _vec3(local.min(axis=0)), _vec3(local.max(axis=0))

    # --- spawning and deleting ----------------------------------------------------------------
    def spawn(self, name: str, allow_renaming: bool, uri: str, resource: str, namespace: str,
              pose: State, frame: str = '') -> str:
        """Spawn an entity; its name (EntityError with a spawn code when it cannot)."""
        if len(name) > MAX_NAME_CHARS:
            raise EntityError('name_invalid', f'the name has {len(name)} characters (at most '
                              f'{MAX_NAME_CHARS})')
        if namespace and (len(namespace) > MAX_NAME_CHARS or not _NAMESPACE.match(namespace)):
            raise EntityError('namespace_invalid', f'{namespace[:80]!r} is not a ROS namespace '
                              f'(of at most {MAX_NAME_CHARS} characters)')
        if len(uri) > MAX_URI_CHARS:
            raise EntityError('unsupported_format', f'the uri has {len(uri)} characters (at '
                              f'most {MAX_URI_CHARS})')
        spawned = self.spawned_count()
        if spawned >= MAX_SPAWNED:
            raise EntityError('failed', f'{spawned} spawned entities already (at most '
                              f'{MAX_SPAWNED} at once): delete some first')
        pose = self._in_world(pose, frame)
        if uri.startswith('material://'):
            return self._spawn_material(name, allow_renaming, uri, pose)
        if uri.startswith('shape://'):
            return self._spawn_shape(name, allow_renaming, uri, pose, namespace)
        if uri or resource:
            return self._spawn_urdf(name, allow_renaming, uri, resource, pose, namespace)
        raise EntityError('no_resource', 'both uri and resource_string are empty')

    def spawned_count(self) -> int:
        """The spawned entities alive now (shapes, URDFs and materials)."""
        return len(self._spawned) + sum(1 for m in self._world.materials if m.name)

    def _name(self, wanted: str, allow_renaming: bool, default: str) -> str:
        taken = set(self.names())
        if wanted and not _NAME.match(wanted):
            if not allow_renaming:
                raise EntityError('name_invalid', f'{wanted!r} is not a valid name (a letter, '
                                  'then letters, digits and underscores)')
            wanted = ''
        if wanted and _MATERIAL_NAME.match(wanted):
            raise EntityError('name_invalid', f'{wanted!r}: names material_<n> are the cell\'s '
                              'materials\'')
        if not wanted and not allow_renaming:
            raise EntityError('name_invalid', 'no name given, and renaming not allowed')
        if wanted and wanted not in taken:
            return wanted
        if wanted and not allow_renaming:
            raise EntityError('name_not_unique', f'an entity named {wanted!r} exists')
        base = wanted or default
        k = 1
        while f'{base}_{k}' in taken:
            k += 1
        return f'{base}_{k}'

    def _spawn_material(self, name: str, allow_renaming: bool, uri: str, pose: State) -> str:
        source = self._world.source
        if source is None:
            raise EntityError('unsupported_format', 'this world has no materials to spawn')
        color = uri[len('material://'):]
        classes = [c for c, _ in source.config.counts]
        if color not in classes:
            raise EntityError('not_found', f'no material class {color!r} in this world '
                              f'(classes: {", ".join(classes)})')
        final = self._name(name, allow_renaming, f'spawned_{color}')
        material = source.spawn(color, pose.position, pose.orientation, self._now())
        material.name = final
        self._check_clear(material.body, final, lambda: source.remove(material))
        self._p.resetBaseVelocity(material.body, pose.linear, pose.angular)
        return final

    def _spawn_shape(self, name: str, allow_renaming: bool, uri: str, pose: State,
                     namespace: str) -> str:
        parsed = urlparse(uri)
        kind, query = parsed.netloc, parse_qs(parsed.query)
        mass = _number(query, 'mass', 0.1, 0.0, MAX_MASS_KG)
        rgba = self._color(query.get('color', ['0.6,0.6,0.6'])[0])
        if kind == 'box':
            size = _numbers(query, 'size', 3)
            half = (size[0] / 2, size[1] / 2, size[2] / 2)
            col = self._p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
            vis = self._p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
        elif kind == 'cylinder':
            radius = _number(query, 'radius', None, 1e-4, MAX_SIZE_M)
            length = _number(query, 'length', None, 1e-4, MAX_SIZE_M)
            half = (radius, radius, length / 2)
            col = self._p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=radius,
                                               height=length)
            vis = self._p.createVisualShape(pybullet.GEOM_CYLINDER, radius=radius,
                                            length=length, rgbaColor=rgba)
        elif kind == 'sphere':
            radius = _number(query, 'radius', None, 1e-4, MAX_SIZE_M)
            half = (radius, radius, radius)
            col = self._p.createCollisionShape(pybullet.GEOM_SPHERE, radius=radius)
            vis = self._p.createVisualShape(pybullet.GEOM_SPHERE, radius=radius, rgbaColor=rgba)
        else:
            raise EntityError('unsupported_format', f'shape {kind!r}: the shapes are box, '
                              'cylinder and sphere')
        final = self._name(name, allow_renaming, kind)
        body = self._p.createMultiBody(mass, col, vis, basePosition=pose.position,
                                       baseOrientation=pose.orientation)
        self._check_clear(body, final, lambda: self._p.removeBody(body))
        self._spawned[final] = _Spawned(
            body, Info(STATIC_OBJECT if mass == 0.0 else DYNAMIC_OBJECT,
                       f'a spawned {kind}, {mass:g} kg', ['spawned', 'shape', kind]),
            pose, half, namespace, static=mass == 0.0)
        self._world.adopt(body, final, lambda: self._forget(final))
        if mass > 0.0:
            self._p.resetBaseVelocity(body, pose.linear, pose.angular)
        return final

    def _forget(self, name: str) -> None:
        """A spawned body the world took out (it left the world: free_bodies.py)."""
        self._spawned.pop(name, None)
        self._info.pop(name, None)

    def _color(self, text: str) -> Tuple[float, float, float, float]:
        source = self._world.source
        classes = dict(source.config.colors) if source is not None else {}
        if text in classes:
            return classes[text]
        try:
            values = [float(v) for v in text.split(',')]
        except ValueError:
            values = []
        if len(values) not in (3, 4) or not all(0.0 <= v <= 1.0 for v in values):
            raise EntityError('failed', f'color {text!r}: r,g,b[,a] within 0..1, or a '
                              f'material class ({", ".join(classes) or "none here"})')
        return (values[0], values[1], values[2], values[3] if len(values) == 4 else 1.0)

    def _spawn_urdf(self, name: str, allow_renaming: bool, uri: str, resource: str,
                    pose: State, namespace: str) -> str:
        path = self._resolve(uri) if uri else None
        try:
            text = read_urdf_file(path) if path is not None else resource
            summary = summarise_urdf(text)
            check_meshes(summary, path.parent if path is not None else None, resolve_resource)
        except UrdfProblem as exc:
            raise EntityError(exc.code, f'{uri or "the URDF text"}: {exc}') from None
        default = summary.name if _NAME.match(summary.name) else 'entity'
        final = self._name(name, allow_renaming, default)
        body = self._load_urdf(path, text, pose, uri)
        self._check_clear(body, final, lambda: self._p.removeBody(body))
        start = self.state_of_body(body)
        self._spawned[final] = _Spawned(
            body, Info(OBJECT, f'spawned from {uri or "a URDF string"}',
                       ['spawned', 'urdf']), replace(start, linear=pose.linear,
                                                     angular=pose.angular),
            None, namespace)
        self._world.adopt(body, final, lambda: self._forget(final))
        self._p.resetBaseVelocity(body, pose.linear, pose.angular)
        return final

    def _load_urdf(self, path: Optional[Path], text: str, pose: State, uri: str) -> int:
        """PyBullet's body of a checked URDF: its file, or its text written to a scratch file
        for as long as PyBullet reads it."""
        scratch = None
        if path is None:
            fd, name = tempfile.mkstemp(suffix='.urdf', dir=self._scratch.path)
            with os.fdopen(fd, 'w') as f:
                f.write(text)
            path = scratch = Path(name)
        try:
            return int(self._p.loadURDF(str(path), pose.position, pose.orientation,
                                        flags=URDF_FLAGS))
        except pybullet.error as exc:
            raise EntityError('parse_error', f'{uri or "the URDF"} cannot be loaded: {exc}'
                              ) from None
        finally:
            if scratch is not None:
                scratch.unlink(missing_ok=True)

    def state_of_body(self, body: int) -> State:
        pos, orn = self._frame_pose(body)
        return State(_vec3(pos), _quat(orn))

    @staticmethod
    def _resolve(uri: str) -> Path:
        if uri.startswith('file://'):
            path = Path(unquote(urlparse(uri).path))
        elif uri.startswith('package://') or uri.startswith('/'):
            try:
                path = resolve_resource(uri)
            except (FileNotFoundError, ValueError, KeyError) as exc:
                raise EntityError('not_found', f'{uri}: {exc}') from None
        else:
            raise EntityError('unsupported_format', f'{uri}: the URIs are material://, '
                              'shape://, package://, file:// and absolute paths')
        if path.suffix.lower() != '.urdf':
            raise EntityError('unsupported_format', f'{uri}: only URDF files are spawned here')
        if not path.is_file():
            raise EntityError('not_found', f'{uri}: no such file')
        return path

    def _check_clear(self, body: int, name: str, undo: Callable[[], None]) -> None:
        """Refuse (and undo) a spawn that would sink into another body."""
        for other in range(self._p.getNumBodies()):
            other_id = self._p.getBodyUniqueId(other)
            if other_id == body:
                continue
            points = self._p.getClosestPoints(body, other_id, 0.0)
            deepest = min((p[8] for p in points), default=0.0)
            if deepest < -PENETRATION_M:
                what = self._world.body_name(other_id)
                undo()
                raise EntityError('invalid_pose', f'{name} would be {-deepest * 1000:.0f} mm '
                                  f'inside {what}')

    def delete(self, name: str) -> None:
        e = self._get(name)
        if e.kind == 'robot':
            raise EntityError('failed', f'{name} is a robot of the world (its nodes, topics and '
                              'controllers stay): it cannot be deleted')
        if e.kind == 'scene':
            raise EntityError('failed', f'{name} is part of the world\'s fixed scene: it cannot '
                              'be deleted')
        if e.material is not None:
            for suction in self._world.suctions.values():
                if suction.held is e.material:
                    suction.release(self._world.source)
            assert self._world.source is not None
            self._world.source.remove(e.material)
        else:
            self._world.disown(e.body)
            self._p.removeBody(e.body)
            del self._spawned[name]
        self._info.pop(name, None)

    def delete_spawned(self) -> List[str]:
        """Every spawned entity deleted (ResetSimulation's SCOPE_SPAWNED); their names."""
        names = list(self._spawned) + [m.name for m in self._world.materials if m.name]
        for name in names:
            self.delete(name)
        return names

    def reset_spawned(self) -> None:
        """Every spawned body back at its spawn pose and velocity (a reset of the state;
        spawned materials went with the cell's materials)."""
        for s in self._spawned.values():
            self._place(s.body, s.start)
        for name in list(self._info):
            if name not in {e.name for e in self._all()}:
                del self._info[name]

    # --- what can be spawned, and where ---------------------------------------------------------
    def spawnables(self) -> List[Spawnable]:
        out = []
        source = self._world.source
        if source is not None:
            for c in source.config.classes:
                out.append(Spawnable(f'material://{c.name}', f'a material of class {c.name}: '
                                     f'{c.size * 1000:.0f} mm cube, {c.mass:g} kg',
                                     (c.size / 2,) * 3))
        out += [Spawnable('shape://box?size=0.1,0.1,0.1&mass=0.5&color=0.8,0.2,0.2',
                          'a box: size=x,y,z [m], mass [kg] (0: static), color=r,g,b[,a] or a '
                          'material class'),
                Spawnable('shape://cylinder?radius=0.05&length=0.2&mass=0.5',
                          'a cylinder along z: radius, length [m], mass, color'),
                Spawnable('shape://sphere?radius=0.05&mass=0.2', 'a sphere: radius [m], mass, '
                          'color')]
        for robot in ('mini_robot', 'youbot', 'zu12'):
            out.append(Spawnable(f'package://robot_description/urdf/{robot}.urdf',
                                 f'the {robot} model (a body, without its controllers)'))
        return out

    def named_poses(self) -> List[NamedPose]:
        """Every named obstacle's top face (its centre, its yaw, the face as a box), each
        robot's start pose, and where the belt drops its materials."""
        out = []
        for obstacle in self._world.obstacles.values():
            if not obstacle.name:
                continue
            pos = np.asarray(obstacle.position, float)
            top = pos[2] + _half_height(obstacle)
            orn = self._p.getQuaternionFromEuler((0.0, 0.0, obstacle.yaw))
            (x0, y0), (x1, y1) = _footprint(obstacle)
            out.append(NamedPose(obstacle.name, f'the top of the {obstacle.name}',
                                 ('region' if not obstacle.collision or top < 0.01
                                  else 'obstacle', obstacle.shape),
                                 State((float(pos[0]), float(pos[1]), float(top)), _quat(orn)),
                                 ((x0, y0, float(top)), (x1, y1, float(top) + 0.5))))
        for name, robot in self._world.robots.items():
            start_pos, start_orn = robot.start_pose
            out.append(NamedPose(f'{name}_start', f'where {name} starts', ('start', name),
                                 State(start_pos, start_orn)))
        source, conveyor = self._world.source, self._world.conveyor
        if source is not None and conveyor is not None:
            size = source.config.largest
            orn = self._p.getQuaternionFromEuler((0.0, 0.0, conveyor.config.yaw))
            out.append(NamedPose('belt_drop', 'where the belt\'s materials are dropped (a '
                                 f'{size * 1000:.0f} mm material\'s centre)', ('spawn', 'belt'),
                                 State(_vec3(source.drop_point(size)), _quat(orn))))
        return out

    def close(self) -> None:
        self._scratch.close()


def _vec3(v: Vector) -> Tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _quat(q: Vector) -> Tuple[float, float, float, float]:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _half_height(obstacle: ObstacleConfig) -> float:
    shape, size = obstacle.shape, obstacle.size
    if shape == 'box':
        return float(size[2]) / 2
    if shape == 'cylinder':
        return float(size[1]) / 2
    return float(size[0])


def _footprint(obstacle: ObstacleConfig) -> Tuple[Tuple[float, float], Tuple[float, float]]:
    """The world-aligned box an obstacle covers on the floor (x, y lower; x, y upper)."""
    x, y = float(obstacle.position[0]), float(obstacle.position[1])
    if obstacle.shape != 'box':
        r = float(obstacle.size[0])
        return (x - r, y - r), (x + r, y + r)
    c, s = abs(math.cos(obstacle.yaw)), abs(math.sin(obstacle.yaw))
    hx, hy = float(obstacle.size[0]) / 2, float(obstacle.size[1]) / 2
    ex, ey = c * hx + s * hy, s * hx + c * hy
    return (x - ex, y - ey), (x + ex, y + ey)


def _filter_pattern(pattern: str) -> Optional['re2._Regexp']:
    """A client's name filter compiled by RE2, which matches in time linear in the name
    (Python's re backtracks: one pattern could hold the node for minutes); None for none."""
    if not pattern:
        return None
    if len(pattern) > MAX_FILTER_CHARS:
        raise EntityError('failed', f'the name filter has {len(pattern)} characters (at most '
                          f'{MAX_FILTER_CHARS})')
    try:
        return re2.compile(pattern, _RE2_OPTIONS)
    except re2.error as exc:
        why = exc.args[0].decode(errors='replace') if exc.args and isinstance(
            exc.args[0], bytes) else str(exc)
        raise EntityError('failed', f'the name filter {pattern[:80]!r} is not a regular '
                          f'expression RE2 takes: {why}') from None


def _check_tags(tags: Sequence[str], what: str) -> None:
    if len(tags) > MAX_TAGS or any(len(t) > MAX_NAME_CHARS for t in tags):
        raise EntityError('failed', f'{what}: at most {MAX_TAGS} tags of at most '
                          f'{MAX_NAME_CHARS} characters')


def _number(query: Dict[str, List[str]], key: str, default: Optional[float], lo: float,
            hi: float) -> float:
    if key not in query:
        if default is None:
            raise EntityError('failed', f'the shape needs {key}=')
        return default
    try:
        value = float(query[key][0])
    except ValueError:
        raise EntityError('failed', f'{key}={query[key][0]!r} is not a number') from None
    if not (math.isfinite(value) and lo <= value <= hi):
        raise EntityError('failed', f'{key}={value:g} is outside {lo:g}..{hi:g}')
    return value


def _numbers(query: Dict[str, List[str]], key: str, count: int) -> List[float]:
    if key not in query:
        raise EntityError('failed', f'the shape needs {key}= ({count} numbers)')
    try:
        values = [float(v) for v in query[key][0].split(',')]
    except ValueError:
        raise EntityError('failed', f'{key}={query[key][0]!r}: {count} numbers') from None
    if len(values) != count or not all(math.isfinite(v) and 1e-4 <= v <= MAX_SIZE_M
                                       for v in values):
        raise EntityError('failed', f'{key}: {count} sizes within 0.0001..{MAX_SIZE_M:g} m')
    return values


