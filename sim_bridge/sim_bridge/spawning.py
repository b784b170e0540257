"""Spawning into the world for the simulation interfaces (no ROS): a material of the world's
classes (``material://<class>``), a box, cylinder or sphere
(``shape://box?size=x,y,z&mass=m&color=r,g,b``), or a URDF (``package://``, ``file://``, a path,
or the URDF text itself, checked before PyBullet reads it); what can be spawned, and the named
poses to spawn at. The ``Spawner`` is the only writer of the spawned bodies' records."""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Callable, Dict, List, Optional, Protocol, Tuple
from urllib.parse import parse_qs, unquote, urlparse

import numpy as np
import pybullet

from sim_bridge.entity_types import (
    DYNAMIC_OBJECT,
    MATERIAL_NAME,
    MAX_MASS_KG,
    MAX_NAME_CHARS,
    MAX_SIZE_M,
    MAX_SPAWNED,
    MAX_URI_CHARS,
    NAME,
    NAMESPACE,
    OBJECT,
    PENETRATION_M,
    SCRATCH_PREFIX,
    STATIC_OBJECT,
    EntityError,
    Info,
    NamedPose,
    Spawnable,
    Spawned,
    State,
    quat,
    vec3,
)
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


class Registry(Protocol):
    """What a spawn asks of the world's entities (entities.py's Entities)."""

    def names(self) -> List[str]: ...

    def in_world(self, state: State, frame: str) -> State: ...

    def state_of_body(self, body: int) -> State: ...

    def forget_info(self, name: str) -> None: ...


class Spawner:
    """Spawns into ``world``; ``now`` gives the simulated time [s] for a spawned material's
    record; ``registry``: the entities, for their names and frames."""

    def __init__(self, world: SimWorld, now: Callable[[], float], registry: Registry) -> None:
        self._world, self._p, self._now, self._registry = world, world.client, now, registry
        self.spawned: Dict[str, Spawned] = {}
        # Where a URDF sent as text is written for PyBullet to read, for as long as that takes.
        self._scratch = ScratchDir(SCRATCH_PREFIX)

    def remove(self, name: str) -> None:
        """A spawned body deleted."""
        body = self.spawned.pop(name).body
        self._world.disown(body)
        self._p.removeBody(body)

    def spawn(self, name: str, allow_renaming: bool, uri: str, resource: str, namespace: str,
              pose: State, frame: str = '') -> str:
        """Spawn an entity; its name (EntityError with a spawn code when it cannot)."""
        if len(name) > MAX_NAME_CHARS:
            raise EntityError('name_invalid', f'the name has {len(name)} characters (at most '
                              f'{MAX_NAME_CHARS})')
        if namespace and (len(namespace) > MAX_NAME_CHARS or not NAMESPACE.match(namespace)):
            raise EntityError('namespace_invalid', f'{namespace[:80]!r} is not a ROS namespace '
                              f'(of at most {MAX_NAME_CHARS} characters)')
        if len(uri) > MAX_URI_CHARS:
            raise EntityError('unsupported_format', f'the uri has {len(uri)} characters (at '
                              f'most {MAX_URI_CHARS})')
        spawned = self.spawned_count()
        if spawned >= MAX_SPAWNED:
            raise EntityError('failed', f'{spawned} spawned entities already (at most '
                              f'{MAX_SPAWNED} at once): delete some first')
        pose = self._registry.in_world(pose, frame)
        if uri.startswith('material://'):
            return self._spawn_material(name, allow_renaming, uri, pose)
        if uri.startswith('shape://'):
            return self._spawn_shape(name, allow_renaming, uri, pose, namespace)
        if uri or resource:
            return self._spawn_urdf(name, allow_renaming, uri, resource, pose, namespace)
        raise EntityError('no_resource', 'both uri and resource_string are empty')

    def spawned_count(self) -> int:
        """The spawned entities alive now (shapes, URDFs and materials)."""
        return len(self.spawned) + sum(1 for m in self._world.materials if m.name)

    def _name(self, wanted: str, allow_renaming: bool, default: str) -> str:
        taken = set(self._registry.names())
        if wanted and not NAME.match(wanted):
            if not allow_renaming:
                raise EntityError('name_invalid', f'{wanted!r} is not a valid name (a letter, '
                                  'then letters, digits and underscores)')
            wanted = ''
        if wanted and MATERIAL_NAME.match(wanted):
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
        self.spawned[final] = Spawned(
            body, Info(STATIC_OBJECT if mass == 0.0 else DYNAMIC_OBJECT,
                       f'a spawned {kind}, {mass:g} kg', ['spawned', 'shape', kind]),
            pose, half, namespace, static=mass == 0.0)
        self._world.adopt(body, final, lambda: self._forget(final))
        if mass > 0.0:
            self._p.resetBaseVelocity(body, pose.linear, pose.angular)
        return final

    def _forget(self, name: str) -> None:
        """A spawned body the world took out (it left the world: free_bodies.py)."""
        self.spawned.pop(name, None)
        self._registry.forget_info(name)

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
        default = summary.name if NAME.match(summary.name) else 'entity'
        final = self._name(name, allow_renaming, default)
        body = self._load_urdf(path, text, pose, uri)
        self._check_clear(body, final, lambda: self._p.removeBody(body))
        start = self._registry.state_of_body(body)
        self.spawned[final] = Spawned(
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

    def close(self) -> None:
        self._scratch.close()


def named_poses(world: SimWorld) -> List[NamedPose]:
    """Every named obstacle's top face (its centre, its yaw, the face as a box), each
    robot's start pose, and where the belt drops its materials."""
    out = []
    for obstacle in world.obstacles.values():
        if not obstacle.name:
            continue
        pos = np.asarray(obstacle.position, float)
        top = pos[2] + _half_height(obstacle)
        orn = world.client.getQuaternionFromEuler((0.0, 0.0, obstacle.yaw))
        (x0, y0), (x1, y1) = _footprint(obstacle)
        out.append(NamedPose(obstacle.name, f'the top of the {obstacle.name}',
                             ('region' if not obstacle.collision or top < 0.01
                              else 'obstacle', obstacle.shape),
                             State((float(pos[0]), float(pos[1]), float(top)), quat(orn)),
                             ((x0, y0, float(top)), (x1, y1, float(top) + 0.5))))
    for name, robot in world.robots.items():
        start_pos, start_orn = robot.start_pose
        out.append(NamedPose(f'{name}_start', f'where {name} starts', ('start', name),
                             State(start_pos, start_orn)))
    source, conveyor = world.source, world.conveyor
    if source is not None and conveyor is not None:
        size = source.config.largest
        orn = world.client.getQuaternionFromEuler((0.0, 0.0, conveyor.config.yaw))
        out.append(NamedPose('belt_drop', 'where the belt\'s materials are dropped (a '
                             f'{size * 1000:.0f} mm material\'s centre)', ('spawn', 'belt'),
                             State(vec3(source.drop_point(size)), quat(orn))))
    return out


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
