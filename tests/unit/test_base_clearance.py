"""The simulator's watch of the mobile bases (sim_bridge/base_clearance.py): each base's footprint
from its base and wheels, the closest approach of two bases at any physics step by the ground
truth, told to the sink as it falls, and the record that keeps it read back checked."""
import math

import pytest

from sim_bridge.base_clearance import TELL_DROP_M, BaseClearance, footprint
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from trial_record.result import ResultError, TrialResult
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world

TWO = 'package://world_description/worlds/cell_two_youbots.yaml'


class Told(NullSink):
    def __init__(self):
        self.told = []

    def on_bases_closest(self, closest):
        self.told.append(closest)


@pytest.fixture(scope='module')
def fleet():
    world = SimWorld(load_world(resolve_resource(TWO)))
    yield world
    world.close()


def test_a_youbots_footprint_is_its_base_and_wheels(fleet):
    fp = footprint(fleet.robots['youbot'])
    # The box (0.57 m long) and the wheels' outer faces (0.209 m from base_link), to a few mm.
    assert fp.half_length == pytest.approx(0.29, abs=0.01)
    assert fp.half_width == pytest.approx(0.21, abs=0.01)
    other = footprint(fleet.robots['youbot2'])
    assert (other.half_length, other.half_width) == pytest.approx(
        (fp.half_length, fp.half_width), abs=1e-3)


def test_the_closest_approach_is_watched_at_every_step_and_told_as_it_falls(fleet):
    runner = SimRunner(fleet, DriveLimits(max_speed=0.8), 100.0)
    sink = Told()
    runner.advance(2, sink)
    parked = runner.clearance.closest.distance
    # The parks are 1.6 m and 0.8 m apart in x and y: well apart, told once.
    assert 0.5 < parked < 1.5 and len(sink.told) == 1
    assert set(sink.told[0].robots) == {'youbot', 'youbot2'}
    # youbot drives towards youbot2's park: the closest falls, and is told as it falls by
    # TELL_DROP_M or more.
    for _ in range(40):
        runner.command('youbot', 0.5, 0.4, 0.0)
        runner.advance(6, sink)
    closest = runner.clearance.closest
    assert closest.distance < parked - 0.3 and closest.time > 0.0
    assert sink.told[-1].distance <= closest.distance + TELL_DROP_M
    falls = [a.distance - b.distance for a, b in zip(sink.told, sink.told[1:])]
    assert all(f > 0.0 for f in falls)
    runner.reset()
    assert runner.clearance.closest.distance == math.inf


def test_one_base_is_not_watched():
    world = SimWorld(load_world(resolve_resource(PIPELINE_CELL)))
    try:
        watch = BaseClearance(world.robots)
        assert not watch.watched and watch.update(1.0) is None
    finally:
        world.close()


def test_a_record_keeps_the_closest_approach_and_reads_it_back_checked():
    record = TrialResult(status='completed', closest_bases={
        'distance': 0.23, 'time': 64.2, 'robots': ['youbot', 'youbot2']}).to_dict()
    assert TrialResult.from_dict(record).closest_bases['robots'] == ['youbot', 'youbot2']
    assert 'closest_bases' not in TrialResult(status='completed').to_dict()
    for bad in ({'distance': -1.0, 'time': 1.0, 'robots': ['a', 'b']},
                {'distance': 0.2, 'time': 1.0, 'robots': ['a']},
                {'distance': 0.2, 'time': 1.0, 'robots': ['a', 'b'], 'extra': 1},
                {'distance': 'near', 'time': 1.0, 'robots': ['a', 'b']}):
        with pytest.raises(ResultError, match='closest_bases'):
            TrialResult.from_dict({**record, 'closest_bases': bad})
