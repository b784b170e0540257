"""The runner's one judgement of a body twist (no ROS): every check a cmd_vel goes through,
and the one (vx, vy, wz) shape from the message to the wheels and back to cmd_vel_out."""
import math

import pytest

from sim_bridge.runner import ZERO, DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from world_description.resources import resolve_resource
from world_description.world_config import load_world


class Applied(NullSink):
    def __init__(self):
        self.commands = []

    def on_command_applied(self, robot, time_ns, command):
        self.commands.append((robot, command))


@pytest.fixture(scope='module', params=['mini_robot', 'youbot'])
def runner(request):
    world = SimWorld(load_world(resolve_resource(
        f'package://world_description/worlds/{request.param}.yaml')))
    yield request.param, SimRunner(world, DriveLimits(max_speed=0.2, max_turn=0.2), 100.0)
    world.close()


def _twist(vx=0.0, vy=0.0, wz=0.0, lz=0.0, ax=0.0, ay=0.0):
    return (vx, vy, lz, ax, ay, wz)


def test_a_good_twist_is_taken_as_vx_vy_wz_and_reaches_the_sink(runner):
    name, r = runner
    r.reset()
    vy = 0.05 if r.holonomic(name) else 0.0
    verdict = r.judge_twist(name, _twist(0.05, vy, 0.1))
    assert verdict.accepted and verdict.notes == ()
    assert verdict.command == (0.05, vy, 0.1)
    sink = Applied()
    r.advance(1, sink)
    # Acceleration limits may ramp it, but the shape is always (vx, vy, wz).
    assert sink.commands and all(len(c) == 3 for _, c in sink.commands)
    assert r.applied(name) == sink.commands[-1][1]


@pytest.mark.parametrize('field', range(6))
def test_a_non_finite_number_in_any_field_stops_the_robot(runner, field):
    name, r = runner
    r.reset()
    r.judge_twist(name, _twist(0.1))
    values = list(_twist(0.1))
    values[field] = math.nan if field % 2 else -math.inf
    verdict = r.judge_twist(name, values)
    assert not verdict.accepted and verdict.command == ZERO
    ((kind, text),) = verdict.notes
    assert kind == 'non-finite' and text.startswith('rejected: non-finite ')
    assert r.guards[name].active_command(r.world.sim_time) == ZERO


@pytest.mark.parametrize('offset, kind', [(-0.6, 'old stamp'), (0.6, 'future stamp'),
                                          (-0.4, ''), (0.4, '')])
def test_a_stamp_further_from_now_than_the_timeout_stops_the_robot(runner, offset, kind):
    name, r = runner
    r.reset()
    r.advance(240, NullSink())
    verdict = r.judge_twist(name, _twist(0.1), stamp=r.world.sim_time + offset)
    if kind:
        assert not verdict.accepted and verdict.notes[0][0] == kind
        assert 'is the sender on simulated time?' in verdict.notes[0][1]
    else:
        assert verdict.accepted and verdict.command == (0.1, 0.0, 0.0)


def test_sideways_speed_is_ignored_by_a_differential_drive_only(runner):
    name, r = runner
    r.reset()
    verdict = r.judge_twist(name, _twist(0.1, 0.1))
    if r.holonomic(name):
        assert verdict.command == (0.1, 0.1, 0.0) and verdict.notes == ()
    else:
        assert verdict.accepted and verdict.command == (0.1, 0.0, 0.0)
        assert [k for k, _ in verdict.notes] == ['sideways']


def test_a_clamped_twist_says_what_was_asked_and_taken_in_the_robots_own_terms(runner):
    name, r = runner
    r.reset()
    verdict = r.judge_twist(name, _twist(5.0, 0.0, -5.0))
    assert verdict.accepted
    ((kind, text),) = verdict.notes
    assert kind == 'clamped'
    limits = r.guards[name].limits
    assert verdict.command == (limits[0], 0.0, -limits[2])
    shown = '(5.000, 0.000, -5.000)' if r.holonomic(name) else '(5.000, -5.000)'
    assert text.startswith(f'{shown} clamped to ')


def test_a_faulted_robot_takes_no_twist_until_reset(runner):
    name, r = runner
    r.reset()
    r.faults[name] = f'{name}: the physics state of base was not finite'
    verdict = r.judge_twist(name, _twist(0.1))
    assert not verdict.accepted and verdict.notes[0][0] == 'fault'
    assert 'reset the simulator to go on' in verdict.notes[0][1]
    r.reset()
    assert r.judge_twist(name, _twist(0.1)).accepted
