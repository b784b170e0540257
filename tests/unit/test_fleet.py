"""Several youBots in one cell: footprints and their clearance, the start-up checks of the
fleet's places and ways (one line naming the robot), and the traffic rules' two shared places
(given in the order asked) and their rule for every drive."""
import copy
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cell_layout.fleet_routes import (
    YOUBOT_FOOTPRINT,
    keeps_clear,
    route_poses,
    way_back,
)
from cell_layout.layout import LayoutError, carries, pool_sides
from cell_layout.world_layout import layout_from_world
from controllers.bezier import BezierPath
from controllers.footprint import Footprint, clearance, polygon_distance
from controllers.path_follower import PathFollower
from coordinator.pipeline.model import BaseReading, Observation
from coordinator.pipeline.traffic import LOADING, STANDS, Traffic
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world, parse_world

TWO = resolve_resource('package://world_description/worlds/cell_two_youbots.yaml')
PAPER = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')


def two_youbots():
    """The two-youBot example as one mapping (its base merged in)."""
    from world_description.world_loading import world_data
    return world_data(TWO)


# --- footprints ---------------------------------------------------------------------------------
def test_footprints_measure_the_gap_between_their_nearest_edges():
    box = Footprint(0.5, 0.25)
    a = box.corners((0.0, 0.0, 0.0))
    assert polygon_distance(a, box.corners((1.3, 0.0, 0.0))) == pytest.approx(0.3)
    # Turned a quarter: its half width now lies along x.
    assert polygon_distance(a, box.corners((1.3, 0.0, math.pi / 2))) == pytest.approx(0.55)
    assert polygon_distance(a, box.corners((0.9, 0.1, 0.3))) == 0.0          # overlapping
    # Corner to corner, diagonally apart.
    d = polygon_distance(a, box.corners((1.3, 0.8, 0.0)))
    assert d == pytest.approx(math.hypot(0.3, 0.3))


def test_the_clearance_of_two_sweeps_is_their_nearest_pair():
    fp = Footprint(0.29, 0.21)
    line = np.array([[x, 0.0, 0.0] for x in np.linspace(0.0, 2.0, 41)])
    parked = np.array([[1.0, 0.9, 0.0]])
    assert clearance(line, fp, parked, fp) == pytest.approx(0.9 - 0.42)
    assert clearance(line, fp, np.zeros((0, 3)), fp) == math.inf
    # The bounding circles skip no nearer pair: the same as measuring every pair.
    rng = np.random.default_rng(3)
    a = rng.uniform(-2, 2, (30, 3))
    b = rng.uniform(-2, 2, (25, 3)) + (3.0, 0.0, 0.0)
    every = min(polygon_distance(fp.corners(p), fp.corners(q)) for p in a for q in b)
    assert clearance(a, fp, b, fp) == pytest.approx(every)


# --- the start-up checks ------------------------------------------------------------------------
def test_the_example_fleet_is_laid_out_and_a_fleet_of_one_is_the_papers():
    layout = layout_from_world(load_world(TWO))
    assert [r.name for r in layout.transports] == ['youbot', 'youbot2'] and layout.fleet
    assert layout.youbot_home == pytest.approx((0.8, 0.05, -math.pi / 2))
    assert layout.park('youbot') == pytest.approx((0.0, -0.8, 0.0))
    assert layout.park('youbot2') == pytest.approx((1.6, 0.6, -math.pi / 2))
    assert layout.trip_load == 6 and layout.clearance == 0.1
    # The loader's swing clearance: the schema's default, or the world's (the Panda's cell).
    assert layout.swing_clearance == 0.0
    panda = load_world(PAPER.parent / 'cell_panda.yaml')
    assert layout_from_world(panda).swing_clearance == 0.05
    # Its links' clearance: the schema's default (they do not touch the cell).
    assert layout.link_clearance == 0.0
    # Each unloads at a side of the pool of its own: the first at the west (the paper's), the
    # second at the east.
    assert [st.name for st in layout.stands_of('youbot')] == ['pool_left', 'pool_right']
    assert [st.name for st in layout.stands_of('youbot2')] == ['pool_east_right',
                                                               'pool_east_left']
    paper = layout_from_world(load_world(PAPER))
    assert not paper.fleet and paper.park('youbot') == paper.youbot_home
    # The way back home is the one the paper's youBot always drove.
    assert paper.via_back == way_back(paper.stands, paper.youbot_home)


def _without(data, key):
    data = copy.deepcopy(data)
    del data['cell'][key]
    return data


def _with_crate(data, x, y):
    data = copy.deepcopy(data)
    data.setdefault('obstacles', []).append({'name': 'crate', 'shape': 'box',
                                             'size': [0.2, 0.2, 0.3], 'position': [x, y, 0.15]})
    return data


def test_a_youbot_backs_off_its_stand_away_from_the_pool_before_it_turns_for_its_park():
    """Turning at once, half way to the north-east park, the base's footprint swept over the
    corner of the pool's north wall (0 cm by the footprint): it backs off first, sideways off its
    stand's line away from the pool, at either side of the pool."""
    from cell_layout.fleet_routes import (
        STAND_BACK_OFF_M,
        _box_clearance,
        _obstacle_boxes,
        way_to_park,
    )
    world = load_world(TWO)
    layout = layout_from_world(world)
    walls = [box for name, box in _obstacle_boxes(world.obstacles) if name.startswith('pool')]
    pool_x = layout.regions['pool_floor'].center[0]
    for robot in ('youbot', 'youbot2'):
        park = layout.park(robot)
        for st in layout.stands_of(robot):
            off = way_to_park(layout, st, park)[0]
            # Sideways off its line (the stands face along y), away from the pool.
            away = math.copysign(1.0, st.pose[0] - pool_x)
            assert off[0] == pytest.approx(st.pose[0] + away * STAND_BACK_OFF_M)
            assert off[1] == pytest.approx(st.pose[1])
            poses = route_poses(st.pose, park, way_to_park(layout, st, park))
            assert min(_box_clearance(poses, box) for box in walls) > 0.02
    # The west's old way to the north-east park: straight from the stand, over the wall.
    west = layout.stands_of('youbot')
    right = next(st for st in west if st.row == -1)
    park = layout.park('youbot2')
    straight = route_poses(right.pose, park, way_back(west, park))
    assert min(_box_clearance(straight, box) for box in walls) == 0.0


def _moved(data, robot, **pose):
    data = copy.deepcopy(data)
    next(r for r in data['robots'] if r['name'] == robot)['pose'].update(pose)
    return data


@pytest.mark.parametrize('change, why', [
    (lambda d: _without(d, 'loading'), 'has 2 youBots: its cell section gives the loading '
                                         'pose'),
    (lambda d: _moved(d, 'youbot2', x=0.7, y=-0.45), r'robot youbot2: its start pose is within '
                                                      r'0.1 m of the loading pose'),
    (lambda d: _moved(d, 'youbot', x=1.6, y=-0.45), r'robot youbot2?: its way from .* passes '
                                                    r'0\.\d\d m from youbot2?\'s start pose'),
    (lambda d: _moved(d, 'youbot2', x=0.2, y=-0.8, yaw=0.0), r'robot youbot2?: its start pose is '
                                                              r'within 0.1 m of youbot2?\'s'),
    (lambda d: _moved(d, 'youbot2', x=2.1, y=-1.9, yaw=0.0), 'robot youbot2: its start pose '
                                                             'overlaps obstacle pool_platform'),
    (lambda d: _moved(d, 'youbot2', z=0.2), 'robot youbot2: it stands 0.2 m high'),
    (lambda d: _with_crate(d, 0.4, -0.4), 'robot youbot: its way from its park to the loading '
                                          'pose runs over obstacle crate'),
])
def test_a_fleet_that_cannot_share_the_floor_is_refused_in_one_line(change, why):
    data = two_youbots()
    data = change(data)
    with pytest.raises(LayoutError, match=why) as err:
        layout_from_world(parse_world(data))
    assert '\n' not in str(err.value)


def test_the_clearance_and_the_trip_load_are_checked_like_every_number():
    from world_description.world_config import WorldConfigError
    for key, value in (('clearance', -0.1), ('clearance', 2.0), ('trip_load', 2.5),
                       ('trip_load', -1), ('swing_clearance', -0.01),
                       ('swing_clearance', 0.5), ('swing_clearance', 'high'),
                       ('link_clearance', -0.01), ('link_clearance', 0.3)):
        data = two_youbots()
        data['cell'][key] = value
        with pytest.raises(WorldConfigError, match=f'cell.{key}'):
            parse_world(data)


def test_every_way_of_the_example_keeps_clear_of_the_other_parks():
    from cell_layout.fleet_routes import _ways
    layout = layout_from_world(load_world(TWO))
    parks = {n: np.array([layout.park(n)]) for n in ('youbot', 'youbot2')}
    for robot, other in (('youbot', 'youbot2'), ('youbot2', 'youbot')):
        ways = _ways(layout, robot)
        # Out to each stand of its side, back, to its park and between its stands.
        assert len(ways) == 1 + 4 * len(layout.stands_of(robot))
        for way in ways.values():
            assert keeps_clear(layout, way, [parks[other]])
        assert not keeps_clear(layout, ways['its park to the loading pose'], [parks[robot]])


# --- the traffic rules -------------------------------------------------------------------------
def _traffic(layout, drives=None):
    bases = {r.name: SimpleNamespace(follower=(drives or {}).get(r.name))
             for r in layout.transports}
    return Traffic(layout, bases)


def _obs(layout, **poses):
    bases = {r.name: BaseReading(tuple(poses.get(r.name, layout.park(r.name))))
             for r in layout.transports}
    return Observation(0.0, {}, bases)


def test_the_shared_places_are_given_in_the_order_asked():
    layout = layout_from_world(load_world(TWO))
    t = _traffic(layout)
    assert t.ask('youbot', LOADING) and t.ask('youbot', LOADING)     # (held: still its)
    assert not t.ask('youbot2', LOADING)                              # (queued)
    assert t.ask('youbot2', STANDS)
    t.leave('youbot', LOADING)
    assert t.holder[LOADING] is None
    assert t.ask('youbot2', LOADING) and t.queue[LOADING] == []
    # A third asking before the first in the queue comes back: the first is served first.
    t.leave('youbot2', LOADING)
    assert not t.ask('youbot', STANDS)
    t.leave('youbot2', STANDS)
    assert t.ask('youbot', STANDS)


def test_each_side_of_the_pool_is_a_place_of_its_own():
    """The example's youBots unload at once, each at its own side; a youBot that unloads at a
    side waits for it (a third youBot would share the west with the first)."""
    from coordinator.pipeline.traffic import stands_place
    layout = layout_from_world(load_world(TWO))
    t = _traffic(layout)
    west, east = (stands_place(layout.side_of(n)) for n in ('youbot', 'youbot2'))
    assert (west, east) == (STANDS, 'pool side 1')
    assert t.ask('youbot', west) and t.ask('youbot2', east)
    assert not t.ask('youbot2', west)                     # (held by youbot: queued)
    t.leave('youbot', west)
    assert t.ask('youbot2', west)


def test_the_east_side_is_a_fleets_where_the_floor_is_free_and_unloads_into_the_pool_only():
    """The east side's stands are the west's turned half round about the pool's centre (the
    arm's every reach from them the same); one youBot (the paper's, or a fleet of one) unloads
    at the west only, as does a fleet whose floor east of the pool is taken; the east side's
    youBot is never loaded with a class unloaded elsewhere (the platform's blue)."""
    from cell_layout.layout import world_to_base
    layout = layout_from_world(load_world(TWO))
    center = np.array(layout.regions['pool_floor'].center)
    west, east = layout.stands_of('youbot'), layout.stands_of('youbot2')
    for st in west:
        turned = next(e for e in east if e.row == st.row)
        assert np.array(turned.pose[:2]) == pytest.approx(2 * center - st.pose[:2])
        assert math.remainder(turned.pose[2] - st.pose[2] - math.pi, 2 * math.pi) == \
            pytest.approx(0.0, abs=1e-9)
        for a, b in zip(st.drops, turned.drops):
            assert world_to_base(st.pose, a) == pytest.approx(world_to_base(turned.pose, b))
        assert turned.serves == frozenset({'pool_floor'})
    assert carries(layout, 'orange', 'youbot2') and not carries(layout, 'blue', 'youbot2')
    assert carries(layout, 'blue', 'youbot')
    assert layout.free_slots('blue', {}, robot='youbot2') == []
    # Spots of the two sides never nearer than 7 cm (none on another).
    spots = [d[:2] for st in layout.stands for d in st.drops]
    assert min(np.linalg.norm(a - b) for i, a in enumerate(spots) for b in spots[i + 1:]) \
        >= 0.07 - 1e-9
    for one in (layout_from_world(load_world(PAPER)), layout_from_world(parse_world(_sized(1)))):
        assert {st.side for st in one.stands} == {0} and len(pool_sides(one)) == 1
    crowded = layout_from_world(parse_world(_with_crate(two_youbots(), 2.75, -1.2)))
    assert {st.side for st in crowded.stands} == {0}
    assert crowded.side_of('youbot2') == 0 and crowded.stands_of('youbot2') == \
        crowded.stands_of('youbot')


def test_a_youbot_whose_side_is_full_is_done_and_the_other_takes_the_rest():
    """Each side has its own drop spots: a youBot is loaded only with what its side has a
    place for, and one whose side has none left for anything to come takes nothing more."""
    from test_pipeline import FakeCell

    from coordinator.pipeline import Material, Pipeline, Settings
    layout = layout_from_world(load_world(TWO))
    run_ = Pipeline(layout, FakeCell(layout, []), Settings())
    room = run_.transport.room
    orange = Material(1, 'orange', np.zeros(3), 0.0, 3, size=0.05)
    assert room.can_take('youbot') and room.can_take('youbot2')
    assert room.plate_slots(orange, 'youbot2')
    run_.book._dropped = {st.name: set(range(len(st.drops))) for st in layout.stands_of('youbot2')}
    assert not room.plate_slots(orange, 'youbot2') and room.plate_slots(orange, 'youbot')
    assert not room.can_take('youbot2') and room.can_take('youbot')


def test_a_youbot_whose_side_fills_up_goes_to_its_park_and_the_other_carries_the_rest():
    """The example with the east side's stands given one drop spot each (and 9 oranges, so
    that the pool still has a spot for each): the second youBot carries two oranges at most,
    then stands at the loading pose with nothing to take; it drives to its park and folds
    there, and the first carries everything else (the fake cell)."""
    from dataclasses import replace

    from test_pipeline import FakeCell, run
    layout = layout_from_world(load_world(TWO))
    layout = replace(layout, manifest={'purple': 1, 'orange': 9, 'blue': 2},
                     stands=tuple(replace(st, drops=st.drops[:1]) if st.side else st
                                  for st in layout.stands))
    assert sum(len(st.drops) for st in layout.stands) >= 9
    colors = ['orange'] * 4 + ['purple'] + ['orange'] * 3 + ['blue'] + ['orange'] * 2 + ['blue']
    cell = FakeCell(layout, colors, base_loop=True)
    p = run(cell, limit=600.0)
    assert p.result.status == 'completed', p.result
    assert p.result.delivered == 12
    shares = p.result.transports
    assert 1 <= shares['youbot2']['carried'] <= 2
    assert shares['youbot']['carried'] == 11 - shares['youbot2']['carried']
    assert np.array(cell.paths['youbot2'][-1][:2]) == pytest.approx(
        np.array(layout.park('youbot2')[:2]), abs=0.05)


def test_a_youbot_at_the_loading_pose_with_nothing_left_for_it_makes_way():
    """The last orange is given up by the Zu 12 (its grasp fails every time) while the east
    side's youBot waits at the loading pose for it: only blues are left, which it does not
    carry (the platform is the west side's). It drives to its park and folds, the other takes
    the blues, and the run ends (without this it held the loading pose for ever: a timeout)."""
    from dataclasses import replace

    from test_pipeline import FakeCell, run
    layout = replace(layout_from_world(load_world(TWO)),
                     manifest={'purple': 1, 'orange': 7, 'blue': 2})
    colors = ['orange'] * 6 + ['purple', 'orange', 'blue', 'blue']
    cell = FakeCell(layout, colors, base_loop=True, grasp_failures={8: 99})
    p = run(cell, limit=400.0)
    assert p.result.status == 'incomplete' and p.result.failed == 1, p.result
    blues = [e.robot for e in cell.events if e.kind == 'delivered' and e.color == 'blue']
    assert blues == ['youbot', 'youbot']
    assert any(e.kind == 'driving' and e.robot == 'youbot2' and e.detail.startswith('to park')
               for e in cell.events)
    assert np.array(cell.paths['youbot2'][-1][:2]) == pytest.approx(
        np.array(layout.park('youbot2')[:2]), abs=0.05)


def test_the_trip_load_is_a_share_and_the_last_youbot_that_can_take_the_rest_takes_it():
    """The example's youBots set off with six (``trip_load``) while the other may carry some
    of what is to come; once only the platform's blue is left, which the east side's youBot
    does not carry, the west side's takes it on this trip, up to a full plate."""
    from dataclasses import replace

    from test_pipeline import FakeCell

    from coordinator.pipeline import Material, Pipeline, Settings
    base = layout_from_world(load_world(TWO))
    assert base.trip_load == 6
    for oranges, limited in ((7, True), (6, False)):
        layout = replace(base, manifest={'purple': 0, 'orange': oranges, 'blue': 1})
        run_ = Pipeline(layout, FakeCell(layout, []), Settings())
        room = run_.transport.room
        run_.materials.update({10 + k: Material(10 + k, 'orange', np.zeros(3), 0.0, 3,
                                                status='on_plate', slot=k, plate='youbot')
                               for k in range(6)})
        blue = Material(1, 'blue', np.zeros(3), 0.0, 3)
        assert room.can_take('youbot2') is limited          # (an orange still to come)
        assert room.has_room('youbot') is not limited
        assert bool(room.plate_slots(blue, 'youbot')) is not limited


def test_a_fleet_of_one_holds_both_places_and_nothing_holds_its_drives_back():
    layout = layout_from_world(load_world(PAPER))
    t = _traffic(layout)
    assert t.ask('youbot', LOADING) and t.ask('youbot', STANDS)
    t.leave('youbot', LOADING)
    assert t.holder[LOADING] == 'youbot'


def _follower(start, goal, t0=0.0):
    return PathFollower(BezierPath([start, goal]), t0, 0.5, 0.5)


def test_a_drive_starts_only_if_it_keeps_clear_of_the_others_where_they_stand_and_drive():
    layout = layout_from_world(load_world(TWO))
    t = _traffic(layout)
    bay = layout.youbot_home
    # youbot2 to the loading pose while youbot stands at its park: clear.
    assert t.clear('youbot2', _follower(layout.park('youbot2'), bay), _obs(layout))
    # ... while youbot stands at the loading pose: not.
    assert not t.clear('youbot2', _follower(layout.park('youbot2'), bay),
                       _obs(layout, youbot=bay))
    # youbot drives across youbot2's way: held back until youbot's drive has passed.
    crossing = _follower((0.2, 0.6, 0.0), (0.2, -1.9, 0.0))
    t = _traffic(layout, {'youbot': crossing})
    assert not t.clear('youbot2', _follower((-1.0, -1.8, 0.0), (1.2, -1.8, 0.0)),
                       _obs(layout, youbot=(0.2, 0.6, 0.0)))
    ahead = Observation(crossing.end_time + 2.0, {}, {
        'youbot': BaseReading((0.2, -1.9, 0.0)), 'youbot2': BaseReading((-1.0, -1.8, 0.0))})
    far = _follower((-1.0, -1.8, 0.0), (1.2, -1.8, 0.0), ahead.now)
    assert not t.clear('youbot2', far, ahead)       # (it stands on the way now)
    clear_of_it = _follower((-1.0, -1.0, 0.0), (1.2, -1.0, 0.0), ahead.now)
    assert t.clear('youbot2', clear_of_it, ahead)   # (its drive over: only where it stands)


# --- a whole run ------------------------------------------------------------------------------
def test_two_youbots_share_the_carrying_and_their_bases_keep_the_clearance_at_every_step():
    """The fake cell (test_pipeline) with the example's two youBots: every material delivered,
    both carry, the loading pose and the pool held by one at a time, and the bases' footprints
    never nearer than the clearance at any step (the fake's kinematic ground truth)."""
    from test_pipeline import FakeCell, run
    layout = layout_from_world(load_world(TWO))
    colors = ['orange'] * 6 + ['purple'] + ['orange'] * 3 + ['blue'] + ['orange'] * 4 + ['blue']
    cell = FakeCell(layout, colors, base_loop=True)
    p = run(cell, limit=400.0)
    assert p.result.status == 'completed', p.result
    assert p.result.delivered == 16 and p.result.trips >= 2
    departed = [e.robot for e in cell.events if e.kind == 'departing']
    assert set(departed) == {'youbot', 'youbot2'}
    # One youBot at a time at the loading pose: each load is put on the plate of the youBot
    # that stands there.
    bay = np.array(layout.youbot_home[:2])
    for e in (e for e in cell.events if e.kind == 'loaded'):
        k = round(e.time / 0.0333333) - 1
        at_bay = [b for b in cell.bases
                  if np.linalg.norm(cell.paths[b][min(k, len(cell.paths[b]) - 1)][:2] - bay)
                  < 0.05]
        assert len(at_bay) == 1, (e, at_bay)
    a, b = (np.array(cell.paths[n]) for n in ('youbot', 'youbot2'))
    gaps = [polygon_distance(YOUBOT_FOOTPRINT.corners(pa), YOUBOT_FOOTPRINT.corners(pb))
            for pa, pb in zip(a[::3], b[::3])]
    assert min(gaps) >= layout.clearance, min(gaps)
    # Each youBot's arm ends folded, the run's states name each youBot's machine.
    machines = {e.robot for e in cell.events if e.kind == 'state'}
    assert {'loader', 'youbot', 'youbot2'} <= machines
    # Each unloads at its own side of the pool (the east side, the second's); each ends at its
    # park, out of the other's way.
    stands = {r: {e.detail.split(' from ')[1] for e in cell.events
                  if e.kind == 'delivered' and e.robot == r and ' from ' in e.detail}
              for r in ('youbot', 'youbot2')}
    assert stands['youbot'] and stands['youbot'] <= {'pool_left', 'pool_right'}
    assert stands['youbot2'] and stands['youbot2'] <= {'pool_east_left', 'pool_east_right'}
    # (One set off for the pool while the other still unloaded there: with one side, it
    # waited at the loading pose until the other had left the pool.)
    unloading = [e.time for e in cell.events if e.kind == 'delivered' and e.robot == 'youbot2']
    assert any(min(unloading) < e.time < max(unloading) for e in cell.events
               if e.kind == 'departing' and e.robot == 'youbot')
    for name in ('youbot', 'youbot2'):
        assert np.array(cell.paths[name][-1][:2]) == pytest.approx(
            np.array(layout.park(name)[:2]), abs=0.05)


def test_each_youbots_share_of_the_run_is_in_its_result_and_reads_back():
    """The result of a fleet's run says what each youBot did (trips, materials carried and
    delivered, distance driven by its path, time busy and waiting by its states), and the
    shares add up to the run's; the record reads back checked."""
    from test_pipeline import FakeCell, run

    from trial_record.result import ResultError, TrialResult
    from trial_record.scoring import RunTrace, build_result, destinations
    layout = layout_from_world(load_world(TWO))
    colors = ['orange'] * 6 + ['purple'] + ['orange'] * 3 + ['blue'] + ['orange'] * 4 + ['blue']
    cell = FakeCell(layout, colors, base_loop=True)
    p = run(cell, limit=400.0)
    paths = {n: [tuple(q[:2]) for q in cell.paths[n]] for n in ('youbot', 'youbot2')}
    trace = RunTrace(seed=7, belt_speed=layout.belt_speed, mode='lock-step', start=p.start_time,
                     identification_details=[], peaks={}, joint_names={},
                     youbot_path=paths['youbot'], events=p.events, paths=paths)
    out = build_result(p.result, [], [], destinations(layout), trace)
    shares = out.transports
    assert set(shares) == {'youbot', 'youbot2'}
    assert sum(s['trips'] for s in shares.values()) == out.trips
    assert all(s['trips'] >= 1 and s['delivered'] <= s['carried'] for s in shares.values())
    assert sum(s['carried'] for s in shares.values()) == out.loaded
    carried = sum(1 for c in colors if layout.carried(c))
    assert sum(s['delivered'] for s in shares.values()) == carried
    for name, s in shares.items():
        xy = np.array(paths[name])
        assert s['distance'] == pytest.approx(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum(),
                                              abs=1e-3)
        assert s['distance'] > 2.0
        assert s['busy'] > 0 and s['waiting'] > 0
        # (From the start: a youBot waits at its park until its first change of state.)
        done = min([t for t, who, state in out.states if who == name and state == 'done']
                   + [out.completion_time])
        assert s['busy'] + s['waiting'] == pytest.approx(done, abs=2e-3)
        assert len(s['path']) == len(paths[name][::3])
    record = out.to_dict()
    assert TrialResult.from_dict(record).transports == shares
    bad = copy.deepcopy(record)
    bad['transports']['youbot2']['delivered'] = 99
    with pytest.raises(ResultError, match='youbot2: delivered'):
        TrialResult.from_dict(bad)
    bad = copy.deepcopy(record)
    bad['transports']['youbot']['busy'] = -1.0
    with pytest.raises(ResultError, match='transports: youbot: busy'):
        TrialResult.from_dict(bad)
    # One youBot's record has no shares: it stays as it was.
    one = layout_from_world(load_world(PAPER))
    assert not one.fleet
    assert 'transports' not in TrialResult(status='completed').to_dict()


def test_the_published_state_names_each_youbot_of_a_fleet():
    from coordinator.coordinator_node import transport_states
    from coordinator.pipeline.model import TransportState

    def youbot(name, state):
        return SimpleNamespace(robot=name, state=state)
    assert transport_states([youbot('youbot', TransportState.DRIVE)]) == 'drive'
    assert transport_states([youbot('a', TransportState.DRIVE),
                             youbot('b', TransportState.WAIT_BAY)]) == 'a: drive, b: wait_bay'


# --- the fleet's size (cell.youbots) -------------------------------------------------------------
def _sized(count, **cell):
    data = two_youbots()
    data['cell'].update(youbots=count, **cell)
    return data


def test_the_fleets_size_leaves_the_last_youbots_out_of_the_world():
    """``cell.youbots`` keeps the first youBots of the list (a sweep's fleet size): the others
    and the cameras they carry are left out; one youBot that starts away from the loading pose
    is a fleet of one (it waits at its park and drives to be loaded)."""
    data = _sized(1.0)                           # (as a sweep writes it)
    data['cameras'].append({'name': 'rear', 'robot': 'youbot2', 'link': 'base_link',
                            'width': 64, 'height': 48, 'rate': 5.0,
                            'vertical_fov_deg': 60.0})
    world = parse_world(data)
    assert [r.name for r in world.robots] == ['zu12', 'youbot']
    assert [c.name for c in world.cameras] == ['belt_camera']
    assert world.roles.transports == ('youbot',) and world.roles.left_out == ('youbot2',)
    layout = layout_from_world(world)
    assert layout.fleet and layout.park('youbot') == pytest.approx((0.0, -0.8, 0.0))
    assert layout.youbot_home == pytest.approx((0.8, 0.05, -math.pi / 2))
    both = parse_world(_sized(2))
    assert [r.name for r in both.robots] == ['zu12', 'youbot', 'youbot2']
    # A loading pose at the one youBot's start pose is the paper's cell: no parks.
    paper = layout_from_world(parse_world(_moved(_sized(1), 'youbot', x=0.8, y=0.05,
                                                 yaw=-math.pi / 2)))
    assert not paper.fleet


@pytest.mark.parametrize('count, why', [
    (3, r'cell.youbots must be finite and within \[1, 2\], got 3'),
    (0, r'within \[1, 2\], got 0'),
    (1.5, 'must be an integer'),
    ('two', 'must be a number'),
])
def test_a_fleet_size_out_of_its_range_is_refused_in_one_line(count, why):
    with pytest.raises(WorldConfigError, match=why):
        parse_world(_sized(count))


def test_a_smaller_fleet_needs_its_loading_pose():
    data = _without(_sized(1), 'loading')
    with pytest.raises(WorldConfigError, match=r"cell.youbots leaves out \['youbot2'\]: .*"
                                               'cell.loading'):
        parse_world(data)


def test_a_fleet_of_one_carries_everything_from_its_park():
    """The example with one youBot: it drives from its park to be loaded, carries every load,
    and the run completes (the fake cell of test_pipeline)."""
    from test_pipeline import FakeCell, run
    layout = layout_from_world(parse_world(_sized(1)))
    colors = ['orange'] * 6 + ['purple'] + ['orange'] * 3 + ['blue'] + ['orange'] * 4 + ['blue']
    cell = FakeCell(layout, colors, base_loop=True)
    p = run(cell, limit=600.0)
    assert p.result.status == 'completed', p.result
    assert p.result.delivered == 16 and p.result.trips >= 2
    assert {e.robot for e in cell.events if e.kind == 'departing'} == {'youbot'}
    assert set(p.result.transports) == {'youbot'}
    assert p.result.transports['youbot']['carried'] == 15
