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
from dataclasses import replace
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import re2

from sim_bridge.cell import MaterialBody
from sim_bridge.entity_types import (
    DYNAMIC_OBJECT,
    MAX_ANGULAR_SPEED_RAD_S,
    MAX_DESCRIPTION_CHARS,
    MAX_DISTANCE_M,
    MAX_FILTER_CHARS,
    MAX_LINEAR_SPEED_M_S,
    MAX_NAME_CHARS,
    MAX_TAGS,
    OBJECT,
    RE2_OPTIONS,
    ROBOT,
    STATIC_OBJECT,
    WORLD_FRAME,
    Entity,
    EntityError,
    Filters,
    Info,
    State,
    quat,
    vec3,
)
from sim_bridge.spawning import Spawner
from sim_bridge.world import SimWorld

NO_FILTERS = Filters()


class Entities:
    """The entities of ``world``; ``now`` gives the simulated time [s] for a spawned
    material's record."""

    def __init__(self, world: SimWorld, now: Callable[[], float]) -> None:
        self.world = self._world = world
        self._p = world.client
        self._info: Dict[str, Info] = {}           # set by SetEntityInfo
        self.spawner = Spawner(world, now, self)

    # --- what there is ------------------------------------------------------------------------
    def _all(self) -> List[Entity]:
        w = self._world
        out = [Entity(name, robot.body, Info(ROBOT, f'robot {name} ({Path(robot.urdf).name})',
                                              _robot_tags(self._world, name)), 'robot', robot=name)
               for name, robot in w.robots.items()]
        for m in w.materials:
            out.append(Entity(m.name or f'material_{m.index}', m.body, Info(
                OBJECT, f'a {m.color} material, {m.size * 1000:.0f} mm, {m.mass:g} kg',
                ['material', m.color] + (['spawned'] if m.name else [])), 'material',
                material=m))
        for name, body, what in _scene(self._world):
            out.append(Entity(name, body, Info(STATIC_OBJECT, what, ['scene']), 'scene'))
        out += [Entity(name, s.body, s.info, 'spawned', spawned=s)
                for name, s in self.spawner.spawned.items()]
        for e in out:
            if e.name in self._info:
                e.info = self._info[e.name]
        return out

    def _get(self, name: str) -> Entity:
        for e in self._all():
            if e.name == name:
                return e
        raise EntityError('not_found', f'no entity named {name!r}')

    def names(self, filters: Filters = NO_FILTERS) -> List[str]:
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
        return State(vec3(pos), quat(orn), vec3(v), vec3(omega))

    def _frame_pose(self, body: int) -> Tuple[Sequence[float], Sequence[float]]:
        """The base's link frame (PyBullet reports its centre of mass)."""
        com_pos, com_orn = self._p.getBasePositionAndOrientation(body)
        info = self._p.getDynamicsInfo(body, -1)
        inv = self._p.invertTransform(info[3], info[4])
        pos, orn = self._p.multiplyTransforms(com_pos, com_orn, inv[0], inv[1])
        return vec3(pos), quat(orn)

    def set_state(self, name: str, state: State, frame: str = '') -> None:
        e = self._get(name)
        state = self.in_world(state, frame)
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
        self._p.resetBaseVelocity(body, vec3(v), state.angular)

    def _holder(self, material: MaterialBody) -> str:
        for robot, suction in self._world.suctions.items():
            if suction.held is material:
                return f"{robot}'s {suction.link}"
        return ''

    def in_world(self, state: State, frame: str) -> State:
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
            state = State(vec3(p), quat(q), vec3(rot @ state.linear),
                          vec3(rot @ state.angular))
            pos, orn = np.asarray(state.position), np.asarray(state.orientation)
        if float(np.linalg.norm(pos)) > MAX_DISTANCE_M:
            raise EntityError('invalid_pose', f'the position is more than {MAX_DISTANCE_M:g} m '
                              'from the origin')
        return replace(state, orientation=quat(orn / norm))

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
        return vec3(local.min(axis=0)), vec3(local.max(axis=0))

    # --- spawning and deleting ----------------------------------------------------------------
    def state_of_body(self, body: int) -> State:
        pos, orn = self._frame_pose(body)
        return State(vec3(pos), quat(orn))

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
            self.spawner.remove(name)
        self._info.pop(name, None)

    def delete_spawned(self) -> List[str]:
        """Every spawned entity deleted (ResetSimulation's SCOPE_SPAWNED); their names."""
        names = list(self.spawner.spawned) + [m.name for m in self._world.materials if m.name]
        for name in names:
            self.delete(name)
        return names

    def reset_spawned(self) -> None:
        """Every spawned body back at its spawn pose and velocity (a reset of the state;
        spawned materials went with the cell's materials)."""
        for s in self.spawner.spawned.values():
            self._place(s.body, s.start)
        for name in list(self._info):
            if name not in {e.name for e in self._all()}:
                del self._info[name]

    # --- what can be spawned, and where ---------------------------------------------------------

    def forget_info(self, name: str) -> None:
        """An entity gone: the info set for it goes too."""
        self._info.pop(name, None)


def _filter_pattern(pattern: str) -> Optional['re2._Regexp']:
    """A client's name filter compiled by RE2, which matches in time linear in the name
    (Python's re backtracks: one pattern could hold the node for minutes); None for none."""
    if not pattern:
        return None
    if len(pattern) > MAX_FILTER_CHARS:
        raise EntityError('failed', f'the name filter has {len(pattern)} characters (at most '
                          f'{MAX_FILTER_CHARS})')
    try:
        return re2.compile(pattern, RE2_OPTIONS)
    except re2.error as exc:
        why = exc.args[0].decode(errors='replace') if exc.args and isinstance(
            exc.args[0], bytes) else str(exc)
        raise EntityError('failed', f'the name filter {pattern[:80]!r} is not a regular '
                          f'expression RE2 takes: {why}') from None


def _check_tags(tags: Sequence[str], what: str) -> None:
    if len(tags) > MAX_TAGS or any(len(t) > MAX_NAME_CHARS for t in tags):
        raise EntityError('failed', f'{what}: at most {MAX_TAGS} tags of at most '
                          f'{MAX_NAME_CHARS} characters')

def _scene(world: SimWorld) -> List[Tuple[str, int, str]]:
    w = world
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


def _robot_tags(world: SimWorld, name: str) -> List[str]:
    robot = world.robots[name]
    tags = ['robot', 'fixed_base' if robot.config.fixed_base else 'mobile']
    if robot.drive is not None:
        tags.append('mecanum' if robot.config.drive.__class__.__name__ == 'MecanumConfig'
                    else 'differential')
    if robot.controllers:
        tags.append('arm')
    return tags
