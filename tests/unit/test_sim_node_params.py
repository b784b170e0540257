"""The simulator node in-process: parameters are declared, validated, and fail clearly."""
import pytest
import rclpy
import yaml
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter

from sim_bridge.sim_node import SimConfigError, SimNode
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError


def make(context, **overrides):
    return SimNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])


def test_every_parameter_has_a_description(context):
    node = make(context)
    try:
        names = node._parameters.keys() - {'use_sim_time'}
        assert {'world', 'time_step', 'real_time_factor', 'synchronous', 'max_speed',
                'max_turn', 'cmd_vel_timeout', 'use_stamped_vel', 'gui'} <= names
        for name in names:
            assert node.describe_parameter(name).description, name
        ranged = node.describe_parameter('max_speed').floating_point_range[0]
        assert (ranged.from_value, ranged.to_value) == (1e-3, 10.0)
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name, value', [
    ('time_step', 0.5), ('time_step', 0.0), ('real_time_factor', -1.0), ('max_speed', 0.0),
    ('cmd_vel_timeout', -0.5), ('max_turn', 1e9)])
def test_out_of_range_values_fail_at_start(context, name, value):
    with pytest.raises(InvalidParameterValueException):
        make(context, **{name: value})


def test_wrong_type_fails_at_start(context):
    with pytest.raises(rclpy.exceptions.ParameterException):
        make(context, max_speed='fast')


def test_cross_parameter_check(context):
    with pytest.raises(SimConfigError, match='exceeds the physics rate'):
        make(context, time_step=0.01, state_publish_rate=200.0)


def test_missing_world_file(context, tmp_path):
    with pytest.raises(WorldConfigError, match='does not exist'):
        make(context, world=str(tmp_path / 'nope.yaml'))


def test_a_belt_speed_the_belt_cannot_take_is_refused_not_reported_set(context):
    """Issue 15, finding 7: belt_speed -0.5 answered success while the belt ran on at 0.1."""
    from world_description import PIPELINE_CELL
    node = make(context, world=PIPELINE_CELL, belt_speed=0.1)
    try:
        conveyor = node._world.conveyor
        result = node.set_parameters([Parameter('belt_speed', value=-0.5)])[0]
        assert not result.successful and 'forward only' in result.reason
        assert conveyor.speed == 0.1 and node.get_parameter('belt_speed').value == 0.1
        assert node.set_parameters([Parameter('belt_speed', value=0.2)])[0].successful
        assert conveyor.speed == 0.2
        assert node.set_parameters([Parameter('belt_speed', value=-1.0)])[0].successful
        assert conveyor.speed == conveyor.config.belt_speed         # the world file's
    finally:
        node.destroy_node()


def test_acceleration_limits_as_diff_drive_controller_names_them(context, tmp_path):
    """linear.x.max_acceleration and angular.z.max_acceleration limit bases whose world entry
    sets none; a world entry's own max_accel wins."""
    source = resolve_resource('package://world_description/worlds/mini_robot.yaml')
    data = yaml.safe_load(open(source))
    for key in ('max_accel', 'max_turn_accel'):
        del data['robots'][0]['drive'][key]
    bare = tmp_path / 'bare.yaml'
    bare.write_text(yaml.safe_dump(data))
    dt = 1.0 / 240.0
    cases = [(str(bare), {}, None),
             (str(bare), {'linear.x.max_acceleration': 0.5,
                          'angular.z.max_acceleration': 3.0}, (0.5 * dt, 0.5 * dt, 3.0 * dt)),
             (str(source), {'linear.x.max_acceleration': 0.5}, (1.0 * dt, 1.0 * dt, 2.0 * dt))]
    for world, params, expected in cases:
        node = make(context, world=world, **params)
        try:
            assert node._runner._max_change.get('mini_robot') == (
                None if expected is None else pytest.approx(expected))
        finally:
            node.destroy_node()
    with pytest.raises(InvalidParameterValueException):
        make(context, **{'linear.x.max_acceleration': -1.0})


def test_an_arm_held_then_freed_is_reported_both_times_without_taking_the_node_down(context):
    """A hold watch warning (an arm blocked) and then its all-clear (freed) in one run: rclpy
    refused the second from the same call site ('Logger severity cannot be changed between
    calls'), and the simulator died mid-trial."""
    from sim_bridge.hold_watch import HoldReport
    node = make(context, world='package://world_description/worlds/pipeline_cell.yaml')
    try:
        reports = [[HoldReport('zu12/arm_controller', True, 'zu12 held back')],
                   [HoldReport('zu12/arm_controller', False, 'zu12 free again')]] * 2
        node._outputs.hold_watch.update = lambda now: reports.pop(0) if reports else []
        for k in range(4):
            node._outputs.on_state('zu12', k * 1_000_000)
    finally:
        node.destroy_node()


def test_a_joint_driven_past_its_limit_is_told_in_the_form_a_trials_result_reads(context):
    """Issue 48: the simulator's ~/joint_limits statuses, read by the coordinator's parser."""
    import math

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from cell_layout.joint_speeds import driven_past
    from world_description import YOUBOT_WORLD
    node = make(context, world=YOUBOT_WORLD, synchronous=True)
    try:
        robot = node._world.robots['youbot']
        j = robot.joint_index['arm_joint_2']
        node._world.client.resetJointState(robot.body, j, 0.3, 5 * math.pi / 2)   # flung
        node._runner.advance(1, node._outputs)
        [status] = [s for s in node._diagnostics.brake_statuses() if s.hardware_id == 'youbot']
        assert status.level == DiagnosticStatus.WARN
        assert status.name == 'sim_node: youbot joint speed limits'
        [record] = driven_past(DiagnosticArray(status=[status]))
        assert record['joint'] == 'arm_joint_2' and record['count'] == 1
        assert record['ratio'] > 4.0 and record['limit'] == pytest.approx(math.pi / 2)
        assert record['brake'] > 9.5 and record['time'] == pytest.approx(1 / 240, abs=1e-4)
        velocities = robot.sensors.joint_states().velocities
        assert abs(velocities[robot.joint_names.index('arm_joint_2')]) <= math.pi / 2
        node._reset_world()
        assert all(s.level == DiagnosticStatus.OK for s in node._diagnostics.brake_statuses())
    finally:
        node.destroy_node()
