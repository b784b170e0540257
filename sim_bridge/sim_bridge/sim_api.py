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

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Result,
    SimulationState,
    SimulatorFeatures,
    WorldResource,
)
from simulation_interfaces.srv import (
    GetAvailableWorlds,
    GetCurrentWorld,
    GetSimulationState,
    GetSimulatorFeatures,
    LoadWorld,
    ResetSimulation,
    SetSimulationState,
    StepSimulation,
    UnloadWorld,
)

from ros_common.deferred_reply import DeferredReplies
from ros_common.services import SERVICE_QOS
from sim_bridge.entities import Entities
from sim_bridge.entity_services import EntityServices, outcome
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
_STATES = {'playing': SimulationState.STATE_PLAYING, 'paused': SimulationState.STATE_PAUSED,
           'stopped': SimulationState.STATE_STOPPED}


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
            (GetCurrentWorld, 'get_current_world', self._get_current_world),
            (GetAvailableWorlds, 'get_available_worlds', self._unsupported),
            (LoadWorld, 'load_world', self._unsupported),
            (UnloadWorld, 'unload_world', self._unsupported)]
        self.entities = EntityServices(node, entities, now_ns)
        services += self.entities.services()
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
        response.result = outcome()
        return response

    def _set_state(self, request: Any, response: Any) -> Any:
        target, now = request.state.state, self._stepping.state
        S, R = SimulationState, SetSimulationState.Response
        if target not in (S.STATE_PLAYING, S.STATE_PAUSED, S.STATE_STOPPED, S.STATE_QUITTING):
            response.result = outcome(Result.RESULT_FEATURE_UNSUPPORTED,
                                      f'state {target}: no world loading here')
        elif target == S.STATE_QUITTING:
            self._stepping.pause()
            response.result = outcome(message='quitting: sim_node shuts down')
            self._node.get_logger().info('quitting on request (set_simulation_state)')
            self._quit()                  # (the spin ends after this reply)
        elif _STATES.get(now) == target and not self._stepping.stepping:
            response.result = outcome(R.ALREADY_IN_TARGET_STATE, f'already {now}')
        elif target == S.STATE_STOPPED:
            # (The steps being served end first: nothing steps after the reset replied.)
            ended = self._stepping.end_steps('set_simulation_state STOPPED')
            if not self._stepping.synchronous:
                self._stepping.pause()
            done = self._reset()
            self._entities.reset_spawned()
            self._stepping.stopped = True
            response.result = outcome(message=f'stopped: {done}' + (
                f'; {ended}' if ended else ''))
        elif target == S.STATE_PAUSED and self._stepping.stepping:
            ended = self._stepping.end_steps('set_simulation_state PAUSED')
            if not self._stepping.synchronous:
                self._stepping.pause()
            response.result = outcome(message=f'paused: {ended}')
        elif target == S.STATE_PAUSED:
            if now == 'stopped':
                self._stepping.stopped = False
                response.result = outcome()
            else:
                ok, message = self._stepping.pause()
                response.result = outcome(Result.RESULT_OK if ok else R.STATE_TRANSITION_ERROR,
                                          message)
        else:
            ok, message = self._stepping.play()
            response.result = outcome(Result.RESULT_OK if ok else R.STATE_TRANSITION_ERROR,
                                      message)
        return response

    def _reset_simulation(self, request: Any, response: Any) -> Any:
        R = ResetSimulation.Request
        scope = request.scope
        if scope in (R.SCOPE_DEFAULT, R.SCOPE_ALL):
            scope = R.SCOPE_STATE | R.SCOPE_SPAWNED
            note = '; simulated time runs on (SCOPE_TIME is not supported)'
        elif scope & R.SCOPE_TIME:
            response.result = outcome(Result.RESULT_FEATURE_UNSUPPORTED,
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
        response.result = outcome(message='; '.join(done) + note)
        return response

    def _step_simulation(self, request: Any, response: Any) -> Any:
        why = self._cannot_step(request.steps)
        if why:
            response.result = outcome(Result.RESULT_OPERATION_FAILED, why)
            return response

        def done(job: StepJob) -> None:
            response.result = (outcome(Result.RESULT_OPERATION_FAILED, _ended(job))
                               if job.ended_by else outcome())
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
            job.cancel()
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
            result.result = outcome(Result.RESULT_OPERATION_FAILED, 'the simulation plays')
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
            result.result = outcome(Result.RESULT_OPERATION_FAILED, _ended(job))
            goal_handle.abort()
        elif job.canceled and job.remaining:
            result.result = outcome(message=f'canceled after {job.stepped} of {steps} steps')
            goal_handle.canceled()
        else:
            result.result = outcome()
            goal_handle.succeed()
        return result

    def _get_current_world(self, _request: Any, response: Any) -> Any:
        name = re.sub(r'\.ya?ml$', '', self._world_uri.rsplit('/', 1)[-1])
        response.world = WorldResource(name=name, description='the world file sim_node runs')
        response.world.world_resource.uri = self._world_uri
        response.result = outcome()
        return response

    def _unsupported(self, _request: Any, response: Any) -> Any:
        response.result = outcome(Result.RESULT_FEATURE_UNSUPPORTED,
                                  'sim_node runs the world of its parameter "world": no world '
                                  'loading or unloading at run time')
        return response


def _ended(job: StepJob) -> str:
    return f'ended by {job.ended_by} after {job.stepped} of {job.steps} steps'
