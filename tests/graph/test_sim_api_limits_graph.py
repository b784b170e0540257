"""sim_node's standard interfaces against a careless or hostile client on the same domain
(issue 47): no request freezes the node, a stop or a reset ends a long step and says so, and
what would poison the physics is refused. Each request is answered within seconds, and the
node answers others while it is served."""
from action_msgs.msg import GoalStatus
from rosgraph_msgs.msg import Clock
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import EntityFilters, Result, SimulationState, SpawnResult
from simulation_interfaces.msg import SpawnEntity as SpawnRequest
from simulation_interfaces.srv import (
    GetEntities,
    GetEntityState,
    GetSimulationState,
    ResetSimulation,
    SetEntityState,
    SetSimulationState,
    SpawnEntities,
    SpawnEntity,
    StepSimulation,
)
from std_srvs.srv import Trigger

from helpers import ActionUser, wait_for

PIPELINE = 'world:=package://world_description/worlds/pipeline_cell.yaml'
SIM = '/sim_node'
OK = Result.RESULT_OK
# A reply "within seconds" on a machine with both cores busy: the requests below took minutes
# (or forever) before; answered at once, each takes milliseconds.
PROMPT_S = 20.0


def _call(probe, srv, name, timeout=PROMPT_S, **fields):
    return probe.call(srv, f'{SIM}/{name}', srv.Request(**fields), timeout=timeout)


def _now_ns(probe):
    """The simulated time the node says it is (a round trip: it answers between two steps)."""
    stamp = _call(probe, GetEntityState, 'get_entity_state', entity='floor').state.header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _answers(probe):
    """The node answers another client now."""
    state = _call(probe, GetSimulationState, 'get_simulation_state')
    return state.result.result == OK


def _long_step(probe, clock):
    """A step request of 10,000,000 steps (about half an hour here), under way: its future."""
    client = probe.service(StepSimulation, f'{SIM}/step_simulation')
    seen = len(clock)
    future = client.call_async(StepSimulation.Request(steps=10_000_000))
    wait_for(lambda: len(clock) > seen + 5, PROMPT_S, what='the steps to run')
    return future


def _ended(future, cause):
    wait_for(future.done, PROMPT_S, what='the long step\'s reply')
    reply = future.result().result
    assert reply.result == Result.RESULT_OPERATION_FAILED, reply.error_message
    assert f'ended by {cause} after' in reply.error_message


def _stood_still(probe):
    """No step follows: the simulated time is the same after a further round trip."""
    before = _now_ns(probe)
    assert _answers(probe)
    assert _now_ns(probe) == before


def test_hostile_requests_are_answered_at_once_and_leave_the_node_serving(start_node, probe):
    sim = start_node('sim_node', '-p', PIPELINE, '-p', 'synchronous:=true')

    # A filter that backtracks: Python's re spent minutes on it, deaf to every client.
    filters = EntityFilters(filter=r'(\w*\w*\w*\w*\w*\w*\w*\w*)*!')
    reply = _call(probe, GetEntities, 'get_entities', filters=filters)
    assert reply.result.result == OK and list(reply.entities) == []
    assert _answers(probe)

    # 315 kB of "<robot ": two minutes of a regular expression before; a parse error now.
    spawn = SpawnEntity.Request(name='x', resource_string='<robot ' * 45_000)
    spawn.initial_pose.pose.position.z = 1.0
    spawn.initial_pose.pose.orientation.w = 1.0
    reply = probe.call(SpawnEntity, f'{SIM}/spawn_entity', spawn, timeout=PROMPT_S)
    assert reply.result.result == SpawnResult.RESOURCE_PARSE_ERROR, reply.result.error_message

    # 5,000 boxes in one request: deaf for 53 s, then 20 times slower; refused whole now.
    many = SpawnEntities.Request()
    for k in range(5000):
        box = SpawnRequest(name=f'box_{k}')
        box.entity_resource.uri = 'shape://box?size=0.02,0.02,0.02'
        box.initial_pose.pose.position.x = 3.0 + 0.03 * (k % 50)
        box.initial_pose.pose.position.y = 3.0 + 0.03 * (k // 50)
        box.initial_pose.pose.position.z = 0.5
        box.initial_pose.pose.orientation.w = 1.0
        many.spawn_requests.append(box)
    reply = probe.call(SpawnEntities, f'{SIM}/spawn_entities', many, timeout=PROMPT_S)
    assert reply.result.result == Result.RESULT_OPERATION_FAILED
    assert 'at most' in reply.result.error_message
    assert not [n for n in _call(probe, GetEntities, 'get_entities').entities
                if n.startswith('box_')]

    # A velocity of 1e300 m/s: NaN 24 steps later; refused now.
    ball = SpawnEntity.Request(name='ball', uri='shape://sphere?radius=0.05&mass=0.2')
    ball.initial_pose.pose.position.x, ball.initial_pose.pose.position.z = 3.0, 0.5
    ball.initial_pose.pose.orientation.w = 1.0
    assert probe.call(SpawnEntity, f'{SIM}/spawn_entity', ball).result.result == OK
    move = SetEntityState.Request(entity='ball')
    move.state.pose = ball.initial_pose.pose
    move.state.twist.linear.x = 1e300
    reply = _call(probe, SetEntityState, 'set_entity_state', entity='ball', state=move.state)
    assert reply.result.result == SetEntityState.Response.INVALID_POSE
    assert 'velocity' in reply.result.error_message
    assert _call(probe, StepSimulation, 'step_simulation', steps=24).result.result == OK
    state = _call(probe, GetEntityState, 'get_entity_state', entity='ball').state
    assert abs(state.pose.position.x - 3.0) < 0.01
    assert sim.alive() and 'Traceback' not in sim.output()


def test_a_stop_a_pause_or_a_reset_ends_a_long_step_and_says_so(start_node, probe):
    """A step request of 10,000,000 steps runs half an hour: a stop, a pause or a reset ends
    it (its reply says after how many steps), and a reply that says the state changed is
    true: no step follows."""
    start_node('sim_node', '-p', PIPELINE, '-p', 'synchronous:=true', '-p', 'step_chunk:=24')
    clock = probe.collect(Clock, '/clock')
    assert _call(probe, StepSimulation, 'step_simulation', steps=1).result.result == OK

    future = _long_step(probe, clock)
    assert _answers(probe)                       # (between chunks)
    stop = _call(probe, SetSimulationState, 'set_simulation_state',
                 state=SimulationState(state=SimulationState.STATE_STOPPED))
    assert stop.result.result == OK and 'step requests ended' in stop.result.error_message
    _ended(future, 'set_simulation_state STOPPED')
    _stood_still(probe)
    assert _call(probe, GetSimulationState, 'get_simulation_state').state.state == \
        SimulationState.STATE_STOPPED

    future = _long_step(probe, clock)
    reset = _call(probe, ResetSimulation, 'reset_simulation')
    assert reset.result.result == OK and 'step requests ended' in reset.result.error_message
    _ended(future, 'reset_simulation')
    _stood_still(probe)

    future = _long_step(probe, clock)
    paused = _call(probe, SetSimulationState, 'set_simulation_state',
                   state=SimulationState(state=SimulationState.STATE_PAUSED))
    assert paused.result.result == OK, paused.result.error_message
    _ended(future, 'set_simulation_state PAUSED')
    _stood_still(probe)

    # The project's own ~/reset, and the action ended by ~/pause: aborted, with the reason.
    future = _long_step(probe, clock)
    assert probe.call(Trigger, f'{SIM}/reset', Trigger.Request(), timeout=PROMPT_S).success
    _ended(future, 'a reset')
    user = ActionUser(f'{SIM}/simulate_steps', SimulateSteps)
    try:
        user.ready(PROMPT_S)
        feedback = []
        handle = user.send(SimulateSteps.Goal(steps=10_000_000),
                           feedback=lambda f: feedback.append(f.feedback))
        assert handle.accepted
        user.spin_until(lambda: feedback, PROMPT_S, 'feedback')
        pause = probe.call(Trigger, f'{SIM}/pause', Trigger.Request(), timeout=PROMPT_S)
        assert pause.success and 'step requests ended' in pause.message
        result = user.result(handle, PROMPT_S)
        assert result.status == GoalStatus.STATUS_ABORTED
        assert 'ended by a pause' in result.result.result.error_message
    finally:
        user.close()
    _stood_still(probe)
