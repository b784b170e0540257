"""The standard simulator interfaces (ros-simulation/simulation_interfaces, Jazzy) of
``sim_node``: services and an action under the node's name, ``/sim_node/<interface>`` as
Gazebo offers them under ``/gzserver/``.

- ``get_simulator_features`` lists exactly what is served below;
- simulation control: ``get_simulation_state``, ``set_simulation_state`` (playing, paused,
  stopped = reset and paused, quitting), ``reset_simulation`` (scopes: state, spawned;
  simulated time runs on), ``step_simulation`` and the ``simulate_steps`` action (feedback
  after each chunk of ``step_chunk`` steps, cancel);
- entities (entities.py): ``get_entities``, ``get_entities_states``, ``get_entity_state``,
  ``set_entity_state``, ``get_entity_info``, ``set_entity_info``, ``get_entity_bounds``,
  ``spawn_entity``, ``spawn_entities``, ``delete_entity``, ``get_spawnables``,
  ``get_named_poses``, ``get_named_pose_bounds``;
- the world: ``get_current_world``; ``get_available_worlds``, ``load_world`` and
  ``unload_world`` answer FEATURE_UNSUPPORTED (a world is the node's parameter).

The project's own ``~/step``, ``~/reset``, ``~/pause`` and ``~/resume`` stay: ``~/step`` is the
lock-step barrier of the trial runner (it announces the commands a step waits for).
"""
from __future__ import annotations

import re
from typing import Any, Callable, Dict, List, Tuple

from geometry_msgs.msg import Vector3
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Bounds,
    EntityCategory,
    EntityInfo,
    EntityState,
    NamedPose,
    Result,
    SimulationState,
    SimulatorFeatures,
    Spawnable,
    SpawnResult,
    TagsFilter,
    WorldResource,
)
from simulation_interfaces.srv import (
    DeleteEntity,
    GetAvailableWorlds,
    GetCurrentWorld,
    GetEntities,
    GetEntitiesStates,
    GetEntityBounds,
    GetEntityInfo,
    GetEntityState,
    GetNamedPoseBounds,
    GetNamedPoses,
    GetSimulationState,
    GetSimulatorFeatures,
    GetSpawnables,
    LoadWorld,
    ResetSimulation,
    SetEntityInfo,
    SetEntityState,
    SetSimulationState,
    SpawnEntities,
    SpawnEntity,
    StepSimulation,
    UnloadWorld,
)

from ros_common.deferred_reply import DeferredReplies
from ros_common.services import SERVICE_QOS
from ros_common.stamps import stamp_from_ns
from sim_bridge.entities import Entities
from sim_bridge.entity_types import MAX_TAGS, EntityError, Filters, Info, State
from sim_bridge.spawning import named_poses
from sim_bridge.stepping import StepJob, Stepping

F = SimulatorFeatures
FEATURES = [
    F.SPAWNING, F.DELETING, F.NAMED_POSES, F.POSE_BOUNDS, F.ENTITY_TAGS, F.ENTITY_BOUNDS,
    F.ENTITY_BOUNDS_BOX, F.ENTITY_CATEGORIES, F.SPAWNING_RESOURCE_STRING,
    F.ENTITY_STATE_GETTING, F.ENTITY_STATE_SETTING, F.ENTITY_INFO_GETTING,
    F.ENTITY_INFO_SETTING, F.SPAWNABLES, F.SIMULATION_RESET, F.SIMULATION_RESET_STATE,
    F.SIMULATION_RESET_SPAWNED, F.SIMULATION_STATE_GETTING, F.SIMULATION_STATE_SETTING,
    F.SIMULATION_STATE_PAUSE, F.STEP_SIMULATION_SINGLE, F.STEP_SIMULATION_MULTIPLE,
    F.STEP_SIMULATION_ACTION, F.WORLD_INFO_GETTING, F.SPAWNING_ENTITIES]
MAX_STEPS = 10_000_000        # a request's steps (in chunks; a pause, stop or reset ends it)
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
_STATES = {'playing': SimulationState.STATE_PLAYING, 'paused': SimulationState.STATE_PAUSED,
           'stopped': SimulationState.STATE_STOPPED}


def _result(code: int = Result.RESULT_OK, message: str = '') -> Result:
    return Result(result=code, error_message=message)


def _error_result(exc: EntityError, spawn: bool = False) -> Result:
    code = (_SPAWN_CODES.get(exc.code) if spawn else None) or _CODES.get(
        exc.code, SetEntityState.Response.INVALID_POSE if exc.code == 'invalid_pose'
        else Result.RESULT_OPERATION_FAILED)
    return _result(code, str(exc))


class SimulationInterfaces:
    """The interfaces on ``node``: ``reset()`` resets the simulation's state (the project's
    ~/reset) and returns what it did; ``quit()`` ends the node's run; ``world_uri`` is the
    world file in use."""

    def __init__(self, node: Node, stepping: Stepping, entities: Entities,
                 reset: Callable[[], str], quit: Callable[[], None], world_uri: str,
                 now_ns: Callable[[], int]) -> None:
        self._node, self._stepping, self._entities = node, stepping, entities
        self._reset, self._quit = reset, quit
        self._world_uri, self._now_ns = world_uri, now_ns
        services: List[Tuple[Any, str, Callable[[Any, Any], Any]]] = [
            (GetSimulatorFeatures, 'get_simulator_features', self._features),
            (GetSimulationState, 'get_simulation_state', self._get_state),
            (SetSimulationState, 'set_simulation_state', self._set_state),
            (ResetSimulation, 'reset_simulation', self._reset_simulation),
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
            (GetNamedPoseBounds, 'get_named_pose_bounds', self._get_named_pose_bounds),
            (GetCurrentWorld, 'get_current_world', self._get_current_world),
            (GetAvailableWorlds, 'get_available_worlds', self._unsupported),
            (LoadWorld, 'load_world', self._unsupported),
            (UnloadWorld, 'unload_world', self._unsupported)]
        for srv_type, name, callback in services:
            node.create_service(srv_type, f'~/{name}', callback, qos_profile=SERVICE_QOS)
        step = node.create_service(StepSimulation, '~/step_simulation', self._step_simulation,
                                   qos_profile=SERVICE_QOS)
        self._step_replies = DeferredReplies(step)
        self._goals: Dict[bytes, StepJob] = {}
        self._action = ActionServer(
            node, SimulateSteps, '~/simulate_steps', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._on_cancel)

    # --- simulation control ---------------------------------------------------------------------
    def _features(self, _request: Any, response: Any) -> Any:
        response.features.features = list(FEATURES)
        response.features.spawn_formats = ['urdf']
        response.features.custom_info = (
            'sim_node (PyBullet). Spawn: material://<class> (a material of the world), '
            'shape://box?size=x,y,z&mass=m&color=r,g,b[,a] (also cylinder: radius, length; '
            'sphere: radius; mass 0: static), a URDF by package://, file:// or path, or its '
            'text. ResetSimulation: simulated time runs on (no SCOPE_TIME). See '
            'docs/simulation-interfaces.md.')
        return response

    def _get_state(self, _request: Any, response: Any) -> Any:
        response.state.state = _STATES[self._stepping.state]
        response.result = _result()
        return response

    def _set_state(self, request: Any, response: Any) -> Any:
        target, now = request.state.state, self._stepping.state
        S, R = SimulationState, SetSimulationState.Response
        if target not in (S.STATE_PLAYING, S.STATE_PAUSED, S.STATE_STOPPED, S.STATE_QUITTING):
            response.result = _result(Result.RESULT_FEATURE_UNSUPPORTED,
                                      f'state {target}: no world loading here')
        elif target == S.STATE_QUITTING:
            self._stepping.pause()
            response.result = _result(message='quitting: sim_node shuts down')
            self._node.get_logger().info('quitting on request (set_simulation_state)')
            self._quit()                  # (the spin ends after this reply)
        elif _STATES.get(now) == target and not self._stepping.stepping:
            response.result = _result(R.ALREADY_IN_TARGET_STATE, f'already {now}')
        elif target == S.STATE_STOPPED:
            # (The steps being served end first: nothing steps after the reset replied.)
            ended = self._stepping.end_steps('set_simulation_state STOPPED')
            if not self._stepping.synchronous:
                self._stepping.pause()
            done = self._reset()
            self._entities.reset_spawned()
            self._stepping.stopped = True
            response.result = _result(message=f'stopped: {done}' + (
                f'; {ended}' if ended else ''))
        elif target == S.STATE_PAUSED and self._stepping.stepping:
            ended = self._stepping.end_steps('set_simulation_state PAUSED')
            if not self._stepping.synchronous:
                self._stepping.pause()
            response.result = _result(message=f'paused: {ended}')
        elif target == S.STATE_PAUSED:
            if now == 'stopped':
                self._stepping.stopped = False
                response.result = _result()
            else:
                ok, message = self._stepping.pause()
                response.result = _result(Result.RESULT_OK if ok else R.STATE_TRANSITION_ERROR,
                                          message)
        else:
            ok, message = self._stepping.play()
            response.result = _result(Result.RESULT_OK if ok else R.STATE_TRANSITION_ERROR,
                                      message)
        return response

    def _reset_simulation(self, request: Any, response: Any) -> Any:
        R = ResetSimulation.Request
        scope = request.scope
        if scope in (R.SCOPE_DEFAULT, R.SCOPE_ALL):
            scope = R.SCOPE_STATE | R.SCOPE_SPAWNED
            note = '; simulated time runs on (SCOPE_TIME is not supported)'
        elif scope & R.SCOPE_TIME:
            response.result = _result(Result.RESULT_FEATURE_UNSUPPORTED,
                                      'SCOPE_TIME: simulated time runs on after a reset')
            return response
        else:
            note = ''
        done = []
        ended = self._stepping.end_steps('reset_simulation')
        if ended:
            done.append(ended)
        if scope & R.SCOPE_SPAWNED:
            deleted = self._entities.delete_spawned()
            done.append(f'deleted {", ".join(deleted) or "nothing spawned"}')
        if scope & R.SCOPE_STATE:
            done.append(self._reset())
            self._entities.reset_spawned()
        response.result = _result(message='; '.join(done) + note)
        return response

    def _step_simulation(self, request: Any, response: Any) -> Any:
        why = self._cannot_step(request.steps)
        if why:
            response.result = _result(Result.RESULT_OPERATION_FAILED, why)
            return response

        def done(job: StepJob) -> None:
            response.result = (_result(Result.RESULT_OPERATION_FAILED, _ended(job))
                               if job.ended_by else _result())
            self._step_replies.send(job, response)
        job = self._stepping.submit(request.steps, done)
        assert job is not None
        return self._step_replies.later(job)

    def _cannot_step(self, steps: int) -> str:
        if not 1 <= steps <= MAX_STEPS:
            return f'steps must be within 1..{MAX_STEPS}'
        if self._stepping.state == 'playing':
            return 'the simulation is playing: pause it first (set_simulation_state)'
        if self._stepping.full:
            return 'too many step requests wait already: ask again after their replies'
        return ''

    def _on_goal(self, goal: Any) -> GoalResponse:
        why = self._cannot_step(goal.steps)
        if why:
            self._node.get_logger().warn(f'simulate_steps goal rejected: {why}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: Any) -> CancelResponse:
        job = self._goals.get(bytes(goal_handle.goal_id.uuid))
        if job is not None:
            self._stepping.cancel(job)
        return CancelResponse.ACCEPT

    async def _execute(self, goal_handle: Any) -> Any:
        steps = goal_handle.request.steps
        finished: Future = Future()
        result = SimulateSteps.Result()

        def progress(job: StepJob) -> None:
            goal_handle.publish_feedback(SimulateSteps.Feedback(
                completed_steps=job.stepped, remaining_steps=job.remaining))
        job = self._stepping.submit(steps, lambda job: finished.set_result(job), progress)
        if job is None:       # (it began playing between the goal's check and now)
            result.result = _result(Result.RESULT_OPERATION_FAILED, 'the simulation plays')
            goal_handle.abort()
            return result
        key = bytes(goal_handle.goal_id.uuid)
        self._goals[key] = job
        try:
            await finished
        finally:
            self._goals.pop(key, None)
        progress(job)
        if job.ended_by:
            result.result = _result(Result.RESULT_OPERATION_FAILED, _ended(job))
            goal_handle.abort()
        elif job.canceled and job.remaining:
            result.result = _result(message=f'canceled after {job.stepped} of {steps} steps')
            goal_handle.canceled()
        else:
            result.result = _result()
            goal_handle.succeed()
        return result

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
            response.result = _result()
        except EntityError as exc:
            response.result = _error_result(exc)
        return response

    def _get_entities_states(self, request: Any, response: Any) -> Any:
        try:
            names = self._entities.names(self._filters(request.filters))
            response.entities = names
            response.states = [self._state_msg(self._entities.state(n)) for n in names]
            response.result = _result()
        except EntityError as exc:
            response.result = _error_result(exc)
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
            response.result = _result()
        except EntityError as exc:
            response.result = _error_result(exc)
        return response

    def _spawn_entity(self, request: Any, response: Any) -> Any:
        response.result, response.entity_name = self._spawn(
            request.name, request.allow_renaming, request.uri, request.resource_string,
            request.entity_namespace, request.initial_pose)
        return response

    def _spawn_entities(self, request: Any, response: Any) -> Any:
        count = len(request.spawn_requests)
        if count > MAX_SPAWN_BATCH:
            response.result = _result(Result.RESULT_OPERATION_FAILED, f'{count} spawn requests '
                                      f'in one call: at most {MAX_SPAWN_BATCH} (nothing was '
                                      'spawned)')
            return response
        for r in request.spawn_requests:
            result, name = self._spawn(r.name, r.allow_renaming, r.entity_resource.uri,
                                       r.entity_resource.resource_string, r.entity_namespace,
                                       r.initial_pose)
            response.results.append(SpawnResult(result=result, entity_name=name))
        failed = [r for r in response.results if r.result.result != Result.RESULT_OK]
        response.result = (_result(SpawnEntities.Response.ENTITIES_SPAWN_FAILED,
                                   f'{len(failed)} of {len(response.results)} failed')
                           if failed else _result())
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
            return _error_result(exc, spawn=True), ''
        self._node.get_logger().info(f'spawned {final} from {uri or "a URDF string"}')
        return _result(), final

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
        response.result = _result(message=f'sources not searched: {unknown}' if unknown else '')
        return response

    def _get_named_poses(self, request: Any, response: Any) -> Any:
        wanted = list(request.tags.tags)
        if len(wanted) > MAX_TAGS:
            response.result = _result(Result.RESULT_OPERATION_FAILED,
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
        response.result = _result()
        return response

    def _get_named_pose_bounds(self, request: Any, response: Any) -> Any:
        pose = next((p for p in named_poses(self._entities.world) if p.name == request.name), None)
        if pose is None:
            response.result = _result(Result.RESULT_NOT_FOUND, f'no named pose {request.name!r}')
        elif pose.box is None:
            response.bounds = Bounds(type=Bounds.TYPE_EMPTY)
            response.result = _result(message='unbounded')
        else:
            lo, hi = pose.box
            response.bounds = Bounds(type=Bounds.TYPE_BOX, points=[
                Vector3(x=lo[0], y=lo[1], z=lo[2]), Vector3(x=hi[0], y=hi[1], z=hi[2])])
            response.result = _result()
        return response

    def _get_current_world(self, _request: Any, response: Any) -> Any:
        name = re.sub(r'\.ya?ml$', '', self._world_uri.rsplit('/', 1)[-1])
        response.world = WorldResource(name=name, description='the world file sim_node runs')
        response.world.world_resource.uri = self._world_uri
        response.result = _result()
        return response

    def _unsupported(self, _request: Any, response: Any) -> Any:
        response.result = _result(Result.RESULT_FEATURE_UNSUPPORTED,
                                  'sim_node runs the world of its parameter "world": no world '
                                  'loading or unloading at run time')
        return response


def _ended(job: StepJob) -> str:
    return f'ended by {job.ended_by} after {job.stepped} of {job.steps} steps'


def _xyz(v: Any) -> Tuple[float, float, float]:
    return (float(v.x), float(v.y), float(v.z))

