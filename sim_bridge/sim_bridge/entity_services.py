"""The entity services of the standard simulator interfaces (simulation_interfaces): listing,
states, info and bounds of the world's entities, spawning and deleting them, what can be spawned
and the named poses; each request turned into a call on the entities (entities.py, spawning.py)
and its EntityError into a result code."""
from __future__ import annotations

from typing import Any, Callable, List, Tuple

from geometry_msgs.msg import Vector3
from rclpy.node import Node
from simulation_interfaces.msg import (
    Bounds,
    EntityCategory,
    EntityInfo,
    EntityState,
    NamedPose,
    Result,
    Spawnable,
    SpawnResult,
    TagsFilter,
)
from simulation_interfaces.srv import (
    DeleteEntity,
    GetEntities,
    GetEntitiesStates,
    GetEntityBounds,
    GetEntityInfo,
    GetEntityState,
    GetNamedPoseBounds,
    GetNamedPoses,
    GetSpawnables,
    SetEntityInfo,
    SetEntityState,
    SpawnEntities,
    SpawnEntity,
)

from ros_common.stamps import stamp_from_ns
from sim_bridge.entities import Entities
from sim_bridge.entity_types import MAX_TAGS, EntityError, Filters, Info, State
from sim_bridge.spawning import named_poses

MAX_SPAWN_BATCH = 64          # SpawnEntities' requests in one call (each about 1-3 ms here)
# EntityError codes as result codes: the standard's, and SpawnEntity's own.
_CODES = {'not_found': Result.RESULT_NOT_FOUND, 'failed': Result.RESULT_OPERATION_FAILED,
          'unsupported': Result.RESULT_FEATURE_UNSUPPORTED}
_SPAWN_CODES = {'invalid_pose': SpawnResult.INVALID_POSE,
                'name_not_unique': SpawnResult.NAME_NOT_UNIQUE,
                'name_invalid': SpawnResult.NAME_INVALID,
                'namespace_invalid': SpawnResult.NAMESPACE_INVALID,
                'unsupported_format': SpawnResult.UNSUPPORTED_FORMAT,
                'no_resource': SpawnResult.NO_RESOURCE,
                'parse_error': SpawnResult.RESOURCE_PARSE_ERROR}

def outcome(code: int = Result.RESULT_OK, message: str = '') -> Result:
    return Result(result=code, error_message=message)


def error_outcome(exc: EntityError, spawn: bool = False) -> Result:
    code = (_SPAWN_CODES.get(exc.code) if spawn else None) or _CODES.get(
        exc.code, SetEntityState.Response.INVALID_POSE if exc.code == 'invalid_pose'
        else Result.RESULT_OPERATION_FAILED)
    return outcome(code, str(exc))


class EntityServices:
    """The entity services' handlers on ``node``, over ``entities``; ``now_ns``: the simulated
    time, for the states' stamps."""

    def __init__(self, node: Node, entities: Entities, now_ns: Callable[[], int]) -> None:
        self._node, self._entities, self._now_ns = node, entities, now_ns

    def services(self) -> List[Tuple[Any, str, Callable[[Any, Any], Any]]]:
        """(type, name, handler) of each service."""
        return [
            (GetEntities, 'get_entities', self._get_entities),
            (GetEntitiesStates, 'get_entities_states', self._get_entities_states),
            (GetEntityState, 'get_entity_state', self._get_entity_state),
            (SetEntityState, 'set_entity_state', self._set_entity_state),
            (GetEntityInfo, 'get_entity_info', self._get_entity_info),
            (SetEntityInfo, 'set_entity_info', self._set_entity_info),
            (GetEntityBounds, 'get_entity_bounds', self._get_entity_bounds),
            (SpawnEntity, 'spawn_entity', self._spawn_entity),
            (SpawnEntities, 'spawn_entities', self._spawn_entities),
            (DeleteEntity, 'delete_entity', self._delete_entity),
            (GetSpawnables, 'get_spawnables', self._get_spawnables),
            (GetNamedPoses, 'get_named_poses', self._get_named_poses),
            (GetNamedPoseBounds, 'get_named_pose_bounds', self._get_named_pose_bounds)]

    # --- entities -------------------------------------------------------------------------------
    def _filters(self, msg: Any) -> Filters:
        b = msg.bounds
        if b.type == Bounds.TYPE_CONVEX_HULL:
            raise EntityError('unsupported', 'convex hull bounds: box and sphere only')
        box = sphere = None
        if b.type == Bounds.TYPE_BOX:
            if len(b.points) != 2:
                raise EntityError('failed', 'box bounds take 2 points')
            box = (_xyz(b.points[0]), _xyz(b.points[1]))
        elif b.type == Bounds.TYPE_SPHERE:
            if len(b.points) != 2 or not b.points[1].x >= 0.0:
                raise EntityError('failed', 'sphere bounds take 2 points: centre, (radius, _, _)')
            sphere = (_xyz(b.points[0]), float(b.points[1].x))
        elif b.type != Bounds.TYPE_EMPTY:
            raise EntityError('failed', f'bounds type {b.type} is none of Bounds\'')
        return Filters(msg.filter, tuple(c.category for c in msg.categories),
                       tuple(msg.tags.tags), msg.tags.filter_mode == TagsFilter.FILTER_MODE_ALL,
                       box, sphere)

    def _get_entities(self, request: Any, response: Any) -> Any:
        try:
            response.entities = self._entities.names(self._filters(request.filters))
            response.result = outcome()
        except EntityError as exc:
            response.result = error_outcome(exc)
        return response

    def _get_entities_states(self, request: Any, response: Any) -> Any:
        try:
            names = self._entities.names(self._filters(request.filters))
            response.entities = names
            response.states = [self._state_msg(self._entities.state(n)) for n in names]
            response.result = outcome()
        except EntityError as exc:
            response.result = error_outcome(exc)
        return response

    def _state_msg(self, state: State) -> EntityState:
        msg = EntityState()
        msg.header.stamp = stamp_from_ns(self._now_ns())
        msg.header.frame_id = 'world'
        p, q = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z = state.position
        q.x, q.y, q.z, q.w = state.orientation
        lin, ang = msg.twist.linear, msg.twist.angular
        lin.x, lin.y, lin.z = state.linear
        ang.x, ang.y, ang.z = state.angular
        return msg

    def _get_entity_state(self, request: Any, response: Any) -> Any:
        return self._entity_call(response, lambda: setattr(
            response, 'state', self._state_msg(self._entities.state(request.entity))))

    def _set_entity_state(self, request: Any, response: Any) -> Any:
        s = request.state
        p, q, lin, ang = s.pose.position, s.pose.orientation, s.twist.linear, s.twist.angular
        state = State((p.x, p.y, p.z), (q.x, q.y, q.z, q.w), _xyz(lin), _xyz(ang))
        return self._entity_call(response, lambda: self._entities.set_state(
            request.entity, state, s.header.frame_id))

    def _get_entity_info(self, request: Any, response: Any) -> Any:
        def fill() -> None:
            info = self._entities.info(request.entity)
            response.info = EntityInfo(category=EntityCategory(category=info.category),
                                       description=info.description, tags=list(info.tags))
        return self._entity_call(response, fill)

    def _set_entity_info(self, request: Any, response: Any) -> Any:
        i = request.info
        return self._entity_call(response, lambda: self._entities.set_info(
            request.entity, Info(i.category.category, i.description, list(i.tags))))

    def _get_entity_bounds(self, request: Any, response: Any) -> Any:
        def fill() -> None:
            lo, hi = self._entities.bounds(request.entity)
            response.bounds = Bounds(type=Bounds.TYPE_BOX, points=[
                Vector3(x=lo[0], y=lo[1], z=lo[2]), Vector3(x=hi[0], y=hi[1], z=hi[2])])
        return self._entity_call(response, fill)

    def _entity_call(self, response: Any, call: Callable[[], None]) -> Any:
        try:
            call()
            response.result = outcome()
        except EntityError as exc:
            response.result = error_outcome(exc)
        return response

    def _spawn_entity(self, request: Any, response: Any) -> Any:
        response.result, response.entity_name = self._spawn(
            request.name, request.allow_renaming, request.uri, request.resource_string,
            request.entity_namespace, request.initial_pose)
        return response

    def _spawn_entities(self, request: Any, response: Any) -> Any:
        count = len(request.spawn_requests)
        if count > MAX_SPAWN_BATCH:
            response.result = outcome(Result.RESULT_OPERATION_FAILED, f'{count} spawn requests '
                                      f'in one call: at most {MAX_SPAWN_BATCH} (nothing was '
                                      'spawned)')
            return response
        for r in request.spawn_requests:
            code, name = self._spawn(r.name, r.allow_renaming, r.entity_resource.uri,
                                       r.entity_resource.resource_string, r.entity_namespace,
                                       r.initial_pose)
            response.results.append(SpawnResult(result=code, entity_name=name))
        failed = [r for r in response.results if r.result.result != Result.RESULT_OK]
        response.result = (outcome(SpawnEntities.Response.ENTITIES_SPAWN_FAILED,
                                   f'{len(failed)} of {len(response.results)} failed')
                           if failed else outcome())
        return response

    def _spawn(self, name: str, allow_renaming: bool, uri: str, resource: str, namespace: str,
               pose: Any) -> Tuple[Result, str]:
        p, q = pose.pose.position, pose.pose.orientation
        try:
            final = self._entities.spawner.spawn(name, allow_renaming, uri, resource, namespace,
                                                 State((p.x, p.y, p.z), (q.x, q.y, q.z, q.w)),
                                                 pose.header.frame_id)
        except EntityError as exc:
            self._node.get_logger().warn(f'spawn_entity {name or uri!r}: {exc}')
            return error_outcome(exc, spawn=True), ''
        self._node.get_logger().info(f'spawned {final} from {uri or "a URDF string"}')
        return outcome(), final

    def _delete_entity(self, request: Any, response: Any) -> Any:
        def delete() -> None:
            self._entities.delete(request.entity)
            self._node.get_logger().info(f'deleted {request.entity}')
        return self._entity_call(response, delete)

    def _get_spawnables(self, request: Any, response: Any) -> Any:
        for s in self._entities.spawner.spawnables():
            bounds = Bounds()
            if s.half_extents is not None:
                h = s.half_extents
                bounds = Bounds(type=Bounds.TYPE_BOX, points=[
                    Vector3(x=-h[0], y=-h[1], z=-h[2]), Vector3(x=h[0], y=h[1], z=h[2])])
            response.spawnables.append(Spawnable(uri=s.uri, description=s.description,
                                                 spawn_bounds=bounds))
        unknown = list(request.sources)
        response.result = outcome(message=f'sources not searched: {unknown}' if unknown else '')
        return response

    def _get_named_poses(self, request: Any, response: Any) -> Any:
        wanted = list(request.tags.tags)
        if len(wanted) > MAX_TAGS:
            response.result = outcome(Result.RESULT_OPERATION_FAILED,
                                      f'{len(wanted)} tags: at most {MAX_TAGS}')
            return response
        every = request.tags.filter_mode == TagsFilter.FILTER_MODE_ALL
        for p in named_poses(self._entities.world):
            if wanted:
                have = [t in p.tags for t in wanted]
                if not (all(have) if every else any(have)):
                    continue
            msg = NamedPose(name=p.name, description=p.description, tags=list(p.tags))
            msg.pose = self._state_msg(p.pose).pose
            response.poses.append(msg)
        response.result = outcome()
        return response

    def _get_named_pose_bounds(self, request: Any, response: Any) -> Any:
        pose = next((p for p in named_poses(self._entities.world) if p.name == request.name), None)
        if pose is None:
            response.result = outcome(Result.RESULT_NOT_FOUND, f'no named pose {request.name!r}')
        elif pose.box is None:
            response.bounds = Bounds(type=Bounds.TYPE_EMPTY)
            response.result = outcome(message='unbounded')
        else:
            lo, hi = pose.box
            response.bounds = Bounds(type=Bounds.TYPE_BOX, points=[
                Vector3(x=lo[0], y=lo[1], z=lo[2]), Vector3(x=hi[0], y=hi[1], z=hi[2])])
            response.result = outcome()
        return response


def _xyz(v: Any) -> Tuple[float, float, float]:
    return (float(v.x), float(v.y), float(v.z))
