"""sim_node's standard simulator interfaces (simulation_interfaces, Jazzy), used as any client
would: only the upstream types, over DDS."""
import math

import pytest
from action_msgs.msg import GoalStatus
from rosgraph_msgs.msg import Clock
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Bounds,
    EntityCategory,
    EntityFilters,
    Result,
    SimulationState,
    SimulatorFeatures,
    SpawnResult,
)
from simulation_interfaces.srv import (
    DeleteEntity,
    GetEntities,
    GetEntitiesStates,
    GetEntityBounds,
    GetEntityInfo,
    GetEntityState,
    GetNamedPoses,
    GetSimulationState,
    GetSimulatorFeatures,
    GetSpawnables,
    LoadWorld,
    ResetSimulation,
    SetEntityState,
    SetSimulationState,
    SpawnEntity,
    StepSimulation,
)

from helpers import ActionUser, wait_for

PIPELINE = 'world:=package://world_description/worlds/pipeline_cell.yaml'
OK = Result.RESULT_OK
SIM = '/sim_node'


def _call(probe, srv, name, **fields):
    return probe.call(srv, f'{SIM}/{name}', srv.Request(**fields), timeout=30.0)


def _ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _now(probe):
    """The simulated time [ns] a state's stamp gives, as the simulator answered."""
    return _ns(_call(probe, GetEntityState, 'get_entity_state', entity='floor').state.header.stamp)


def _steps(probe, clock, n):
    """Step ``n`` times; the simulated time that passed [ns]."""
    before = _now(probe)
    reply = _call(probe, StepSimulation, 'step_simulation', steps=n)
    assert reply.result.result == OK, reply.result.error_message
    return _now(probe) - before


@pytest.fixture
def steps_action():
    user = ActionUser(f'{SIM}/simulate_steps', SimulateSteps)
    yield user
    user.close()


def _action(user, steps, cancel_after=None):
    """Send a SimulateSteps goal: its handle, its result (None if rejected), its feedback."""
    user.ready(30.0)
    feedback = []
    handle = user.send(SimulateSteps.Goal(steps=steps),
                       feedback=lambda f: feedback.append(f.feedback))
    if not handle.accepted:
        return handle, None, feedback
    if cancel_after is not None:
        user.spin_until(lambda: feedback and feedback[-1].completed_steps >= cancel_after, 60.0,
                        'feedback')
        canceled = handle.cancel_goal_async()
        user.spin_until(canceled.done, 20.0, 'the cancel')
    return handle, user.result(handle, 120.0), feedback


def test_lock_step_control_entities_and_what_is_not_implemented(start_node, probe,
                                                                steps_action):
    start_node('sim_node', '-p', PIPELINE, '-p', 'synchronous:=true', '-p', 'step_chunk:=240')
    clock = probe.collect(Clock, '/clock')
    features = _call(probe, GetSimulatorFeatures, 'get_simulator_features').features
    for feature in (SimulatorFeatures.STEP_SIMULATION_ACTION, SimulatorFeatures.SPAWNING,
                    SimulatorFeatures.ENTITY_STATE_SETTING, SimulatorFeatures.SIMULATION_RESET):
        assert feature in features.features
    assert SimulatorFeatures.WORLD_LOADING not in features.features
    assert 'urdf' in features.spawn_formats
    state = _call(probe, GetSimulationState, 'get_simulation_state')
    assert state.state.state == SimulationState.STATE_PAUSED     # lock-step: steps on request
    refused = _call(probe, SetSimulationState, 'set_simulation_state',
                    state=SimulationState(state=SimulationState.STATE_PLAYING))
    assert refused.result.result == SetSimulationState.Response.STATE_TRANSITION_ERROR

    # 1000 steps through the action: feedback, then the result; /clock advanced by as much.
    assert _call(probe, StepSimulation, 'step_simulation', steps=1).result.result == OK
    wait_for(lambda: clock, 20.0, what='/clock')
    # (The feedback topic read as any node reads it: rclpy's ActionClient drops what comes for
    # a goal once its result is in, and on a busy machine the last feedback, a topic's message,
    # came after the result, a service's answer. The server publishes it; nothing makes the
    # client's callback get it.)
    published: list = []
    raw = probe.node.create_subscription(
        SimulateSteps.Impl.FeedbackMessage, f'{SIM}/simulate_steps/_action/feedback',
        lambda m: published.append(m), 1000)
    wait_for(lambda: raw.get_publisher_count() >= 1, 30.0, what='the feedback publisher')
    t0 = _now(probe)
    handle, result, feedback = _action(steps_action, 1000)
    assert result.status == GoalStatus.STATUS_SUCCEEDED and result.result.result.result == OK
    goal = bytes(handle.goal_id.uuid)
    wait_for(lambda: any(bytes(m.goal_id.uuid) == goal and m.feedback.completed_steps == 1000
                         for m in list(published)), 20.0, what='the last feedback')
    mine = [m.feedback for m in published if bytes(m.goal_id.uuid) == goal]
    assert mine[-1].remaining_steps == 0
    assert [f.completed_steps for f in mine] == sorted(f.completed_steps for f in mine)
    assert all(f.completed_steps + f.remaining_steps == 1000 for f in mine + feedback)
    assert _now(probe) - t0 == pytest.approx(1000 * 4_166_667, abs=1000)
    # A cancel ends the goal canceled, after the chunk it was in.
    handle, result, feedback = _action(steps_action, 100_000, cancel_after=240)
    assert result.status == GoalStatus.STATUS_CANCELED
    assert 'canceled after' in result.result.result.error_message
    # And the service: 100 steps.
    assert _steps(probe, clock, 100) == pytest.approx(100 * 4_166_667, abs=1000)

    # The cell's entities, filtered.
    names = _call(probe, GetEntities, 'get_entities').entities
    assert {'zu12', 'youbot', 'conveyor', 'ground_target', 'pool_floor'} <= set(names)
    robots = _call(probe, GetEntities, 'get_entities', filters=EntityFilters(
        categories=[EntityCategory(category=EntityCategory.CATEGORY_ROBOT)])).entities
    assert list(robots) == ['zu12', 'youbot']
    bad = _call(probe, GetEntities, 'get_entities', filters=EntityFilters(filter='(['))
    assert bad.result.result == Result.RESULT_OPERATION_FAILED
    hull = _call(probe, GetEntities, 'get_entities',
                 filters=EntityFilters(bounds=Bounds(type=Bounds.TYPE_CONVEX_HULL)))
    assert hull.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    info = _call(probe, GetEntityInfo, 'get_entity_info', entity='youbot').info
    assert info.category.category == EntityCategory.CATEGORY_ROBOT and 'mecanum' in info.tags
    states = _call(probe, GetEntitiesStates, 'get_entities_states',
                   filters=EntityFilters(filter='^(zu12|youbot)$'))
    assert list(states.entities) == ['zu12', 'youbot'] and len(states.states) == 2

    # Move the youBot; it stays where it was put (its drive holds it at rest).
    move = SetEntityState.Request(entity='youbot')
    move.state.pose.position.x, move.state.pose.position.y = 1.2, -0.6
    move.state.pose.position.z = 0.0815
    move.state.pose.orientation.w = 1.0
    assert _call(probe, SetEntityState, 'set_entity_state', entity='youbot',
                 state=move.state).result.result == OK
    _steps(probe, clock, 24)
    pose = _call(probe, GetEntityState, 'get_entity_state', entity='youbot').state.pose
    assert (pose.position.x, pose.position.y) == pytest.approx((1.2, -0.6), abs=0.01)
    fixed = _call(probe, SetEntityState, 'set_entity_state', entity='zu12', state=move.state)
    assert fixed.result.result == Result.RESULT_OPERATION_FAILED
    assert _call(probe, GetEntityState, 'get_entity_state',
                 entity='nobody').result.result == Result.RESULT_NOT_FOUND

    # Spawn a box by the named pose of the ground target; bounds; delete it.
    poses = {p.name: p for p in _call(probe, GetNamedPoses, 'get_named_poses').poses}
    target = poses['ground_target'].pose
    spawn = SpawnEntity.Request(name='crate', uri='shape://box?size=0.1,0.1,0.1&mass=0.5')
    spawn.initial_pose.pose.position.x = target.position.x
    spawn.initial_pose.pose.position.y = target.position.y
    spawn.initial_pose.pose.position.z = target.position.z + 0.1
    spawn.initial_pose.pose.orientation.w = 1.0
    assert probe.call(SpawnEntity, f'{SIM}/spawn_entity', spawn).entity_name == 'crate'
    again = probe.call(SpawnEntity, f'{SIM}/spawn_entity', spawn)
    assert again.result.result == SpawnResult.NAME_NOT_UNIQUE
    _steps(probe, clock, 240)
    crate = _call(probe, GetEntityState, 'get_entity_state', entity='crate').state.pose
    assert crate.position.z == pytest.approx(target.position.z + 0.05, abs=0.005)
    bounds = _call(probe, GetEntityBounds, 'get_entity_bounds', entity='crate').bounds
    assert bounds.type == Bounds.TYPE_BOX and bounds.points[1].x == pytest.approx(0.05)
    spawnables = [s.uri for s in _call(probe, GetSpawnables, 'get_spawnables').spawnables]
    assert 'material://orange' in spawnables
    assert _call(probe, DeleteEntity, 'delete_entity', entity='crate').result.result == OK
    assert _call(probe, DeleteEntity, 'delete_entity',
                 entity='youbot').result.result == Result.RESULT_OPERATION_FAILED

    # Reset: the youBot back at its start; spawned entities gone.
    spawn.name = 'ball'
    spawn.uri = 'shape://sphere?radius=0.05'
    assert probe.call(SpawnEntity, f'{SIM}/spawn_entity', spawn).result.result == OK
    reset = _call(probe, ResetSimulation, 'reset_simulation')
    assert reset.result.result == OK and 'ball' in reset.result.error_message
    time_only = _call(probe, ResetSimulation, 'reset_simulation',
                      scope=ResetSimulation.Request.SCOPE_TIME)
    assert time_only.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    pose = _call(probe, GetEntityState, 'get_entity_state', entity='youbot').state.pose
    assert (pose.position.x, pose.position.y) == pytest.approx((0.8, 0.05), abs=0.005)
    assert 'ball' not in _call(probe, GetEntities, 'get_entities').entities

    # What is not implemented says so, at once.
    load = _call(probe, LoadWorld, 'load_world', uri='any.sdf')
    assert load.result.result == Result.RESULT_FEATURE_UNSUPPORTED


def test_real_time_play_pause_stop_and_step(start_node, probe, steps_action):
    start_node('sim_node', '-p', PIPELINE, '-p', 'real_time_factor:=1.0')
    clock = probe.collect(Clock, '/clock')
    wait_for(lambda: len(clock) > 10, 20.0, what='/clock')
    state = _call(probe, GetSimulationState, 'get_simulation_state').state.state
    assert state == SimulationState.STATE_PLAYING
    # Stepping while playing is refused, and the action's goal too.
    assert _call(probe, StepSimulation, 'step_simulation',
                 steps=10).result.result == Result.RESULT_OPERATION_FAILED
    handle, _, _ = _action(steps_action, 10)
    assert not handle.accepted

    def set_state(target):
        return _call(probe, SetSimulationState, 'set_simulation_state',
                     state=SimulationState(state=target)).result

    assert set_state(SimulationState.STATE_PAUSED).result == OK
    assert set_state(SimulationState.STATE_PAUSED).result == \
        SetSimulationState.Response.ALREADY_IN_TARGET_STATE
    assert _steps(probe, clock, 48) == pytest.approx(48 * 4_166_667, abs=1000)
    # Stopped: reset and paused; playing again from there.
    assert set_state(SimulationState.STATE_STOPPED).result == OK
    assert _call(probe, GetSimulationState,
                 'get_simulation_state').state.state == SimulationState.STATE_STOPPED
    assert set_state(SimulationState.STATE_PLAYING).result == OK
    t = _ns(clock[-1][1].clock)
    wait_for(lambda: _ns(clock[-1][1].clock) > t + 200_000_000, 20.0, what='time running')
    assert not math.isnan(t)


def test_quitting_ends_sim_node(start_node, probe):
    sim = start_node('sim_node', '-p', 'synchronous:=true')
    reply = _call(probe, SetSimulationState, 'set_simulation_state',
                  state=SimulationState(state=SimulationState.STATE_QUITTING))
    assert reply.result.result == OK
    wait_for(lambda: not sim.alive(), 20.0, what='sim_node to quit')
    assert sim.proc.returncode == 0
    assert 'Traceback' not in sim.output()


def test_a_material_spawned_on_the_belt_is_sorted(start_node, probe, tmp_path):
    """A client spawns an orange through spawn_entity (material://orange, on the belt behind
    the plan's first material, upstream of the camera); the coordinator, told the batch has one
    more orange (extra_materials), sorts it with the others: it rests in the pool by the
    ground truth."""
    import json

    import yaml

    from studies.trial_graph import pipeline_graph
    from world_description.resources import resolve_resource
    world = yaml.safe_load(resolve_resource(
        'package://world_description/worlds/pipeline_cell.yaml').read_text())
    world['materials']['counts'] = {'purple': 1, 'orange': 1}
    path = tmp_path / 'small_cell.yaml'
    path.write_text(yaml.safe_dump(world))
    result_file = tmp_path / 'result.json'
    graph = {node.name: node for node in pipeline_graph(11, 0.12, world=str(path),
                                                        result_file=result_file)}
    sim = graph.pop('sim_node')
    start_node(sim.executable, *sim.ros_args()[1:], name='sim_node')
    drop = next(p for p in _call(probe, GetNamedPoses, 'get_named_poses').poses
                if p.name == 'belt_drop').pose
    spawn = SpawnEntity.Request(name='extra', uri='material://orange')
    spawn.initial_pose.pose = drop
    # (The belt runs along +x; the plan's first material drops at belt_drop at the start.)
    spawn.initial_pose.pose.position.x -= 0.08
    reply = probe.call(SpawnEntity, f'{SIM}/spawn_entity', spawn)
    assert reply.result.result == OK and reply.entity_name == 'extra', reply.result
    coordinator = graph.pop('coordinator_node')
    coordinator.parameters['extra_materials'] = ['orange']
    for node in graph.values():
        start_node(node.executable, *node.ros_args()[1:], name=node.name)
    done = start_node(coordinator.executable, *coordinator.ros_args()[1:],
                      name='coordinator_node')
    wait_for(lambda: not done.alive(), 600.0, what='the run')
    result = json.loads(result_file.read_text())
    assert result['status'] == 'completed', (result['message'], result['not_at_destination'])
    assert result['total'] == 3 and result['handled_verified'] == 3
    colors = sorted(m['color'] for m in result['final_materials'])
    assert colors == ['orange', 'orange', 'purple']
    assert all(m['at_destination'] for m in result['final_materials'])
