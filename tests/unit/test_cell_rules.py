"""The coordinator follows the world's rules: each class to its destination by its route, on a
slot of its own; a cell whose rules cannot work is refused at start-up with one line."""
import copy

import numpy as np
import pytest
import yaml
from test_material_classes import PAPER_CLASSES as PAPER
from test_pipeline import FakeCell, kinds, observation, run

from cell_layout.layout import SLOT_GAP_M, LayoutError
from cell_layout.world_layout import layout_from_world
from world_description.resources import resolve_resource
from world_description.world_config import parse_world

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')


def world(classes, obstacles=(), move=None):
    with open(CELL, encoding='utf-8') as f:
        data = yaml.safe_load(f)
    data['materials'] = {k: v for k, v in data['materials'].items()
                         if k not in ('counts', 'colors')}
    data['materials']['classes'] = classes
    data['obstacles'] += [dict(o) for o in obstacles]
    for o in data['obstacles']:
        if move and o['name'] in move:
            o['position'] = move[o['name']]
    return parse_world(data, 'cell.yaml')


def test_every_destination_is_laid_out_in_slots_that_never_overlap():
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    for name, region in layout.regions.items():
        size = max(layout.size_of(c) for c in layout.rules if layout.destination(c) == name)
        x0, x1, y0, y1, _, _ = region.box(size)
        for i, p in enumerate(region.slots):
            if not region.drop:
                assert x0 + size / 2 <= p[0] <= x1 - size / 2
                assert y0 + size / 2 <= p[1] <= y1 - size / 2
            for q in region.slots[i + 1:]:
                assert np.hypot(p[0] - q[0], p[1] - q[1]) >= size + SLOT_GAP_M - 1e-9
    # The ground target's first slot is its centre (where the paper's purple goes).
    assert layout.regions['ground_target'].slots[0][:2] == pytest.approx((-0.5, 0.3))


def test_two_materials_placed_on_one_destination_go_on_slots_of_their_own():
    classes = copy.deepcopy(PAPER)
    classes['purple']['count'] = 3
    classes['orange']['count'] = 4
    layout = layout_from_world(world(classes))
    cell = ReleaseLog(layout, ['orange', 'purple', 'orange', 'purple', 'blue', 'orange',
                               'purple', 'orange'])
    r = run(cell).result
    assert r.status == 'completed', r
    placed = kinds(cell, 'placed')
    assert sorted(e.detail for e in placed) == [f'ground_target slot {k}' for k in range(3)]
    # Where the cup let go of each (the fake's joints are the cup's position): over three
    # points a material's size and the gap apart, each over the ground target.
    on_target = [p for p in cell.releases if p[2] < 0.1]      # (the plate's are higher)
    assert len(on_target) == 3
    x0, x1, y0, y1, _, _ = layout.regions['ground_target'].box(0.05)
    for i, p in enumerate(on_target):
        assert x0 < p[0] < x1 and y0 < p[1] < y1
        for q in on_target[i + 1:]:
            assert np.linalg.norm(p[:2] - q[:2]) >= 0.05 + SLOT_GAP_M - 1e-9


class ReleaseLog(FakeCell):
    """The fake cell, noting where the Zu 12's cup lets go of what it holds."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.releases = []

    def grip(self, arm, on):
        if arm == 'zu12' and not on and self.holding[arm]:
            self.releases.append(self.q[arm][:3].copy())
        return super().grip(arm, on)


def test_a_class_of_the_users_own_goes_where_its_rule_says():
    """A fourth colour, placed by the Zu 12 on a bin of its own beside the ground target."""
    classes = copy.deepcopy(PAPER)
    classes['green'] = {'color': [0.1, 0.8, 0.2, 1.0], 'count': 2, 'destination': 'green_bin',
                        'route': 'place', 'size': 0.04, 'mass': 0.3}
    bin_ = {'name': 'green_bin', 'shape': 'box', 'size': [0.2, 0.2, 0.05],
            'position': [-0.2, -0.55, 0.025], 'color': [0.3, 0.6, 0.3, 1.0]}
    layout = layout_from_world(world(classes, [bin_]))
    assert layout.region_of('green').top == pytest.approx(0.05)
    cell = FakeCell(layout, ['orange', 'green', 'orange', 'purple', 'orange', 'blue', 'orange',
                             'green', 'orange', 'orange'])
    r = run(cell).result
    assert r.status == 'completed', r
    greens = [e for e in kinds(cell, 'placed') if e.color == 'green']
    assert sorted(e.detail for e in greens) == ['green_bin slot 0', 'green_bin slot 1']
    assert len(kinds(cell, 'loaded')) == 7


@pytest.mark.parametrize('change, fragment', [
    # The ground target across the floor, 3 m from the Zu 12.
    (lambda c, o, m: m.update(ground_target=[3.0, 2.0, 0.001]),
     r'destination ground_target is out of the reach of the loader zu12'),
    # The platform carried to, but out by the belt: no stand reaches it.
    (lambda c, o, m: m.update(pool_platform=[-1.5, -1.5, 0.075]),
     r"destination pool_platform is out of the youBot arm's reach"),
    (lambda c, o, m: c['purple'].update(count=12),
     r'destination ground_target has 9 slots in reach for 12 materials'),
    (lambda c, o, m: c['blue'].update(route='place'),
     r'destination pool_platform is out of the reach of the loader'),
    (lambda c, o, m: c['orange'].update(route='place'),
     r"pool_floor is the youBot's: its materials are carried there"),
    (lambda c, o, m: c['purple'].update(destination='pool_floor'),
     r'destination pool_floor is reached by both routes'),
    (lambda c, o, m: c['orange'].update(size=0.07),
     r"orange \(0.07 m\) is too large to be carried: the youBot carries materials of at most "
     r"0.06 m"),
    (lambda c, o, m: c['orange'].update(count=30),
     r'destination pool_floor has \d+ slots in reach for 30 materials'),
    # A load the youBot's arm cannot hold (issue 48): named with its joint and torque.
    (lambda c, o, m: c['orange'].update(mass=2.0),
     r"orange materials \(2 kg\) are more than the youBot's arm holds at rest over its plate: "
     r'arm_joint_\d needs \d+\.\d\d N m there at best, and takes at most 95% of its'),
    (lambda c, o, m: c['blue'].update(mass=0.9),
     r"destination pool_platform is out of the youBot arm's reach from its unload stands beside "
     r'the pool holding 0.9 kg at rest \(it reaches it empty-handed\)'),
])
def test_a_cell_whose_rules_cannot_work_is_refused_with_one_line(change, fragment):
    classes, obstacles, move = copy.deepcopy(PAPER), [], {}
    change(classes, obstacles, move)
    with pytest.raises(LayoutError, match=fragment) as err:
        layout_from_world(world(classes, obstacles, move))
    assert '\n' not in str(err.value)


def test_a_load_larger_than_the_plate_goes_in_as_many_trips_as_it_needs():
    """16 materials of four classes, 14 carried: the plate holds 8. The youBot sets off once
    its plate has no room for what waits, the others queue at the end stop, and the Zu 12
    loads them once it is back; nothing is given up, every pool material has a drop spot of
    its own."""
    classes = copy.deepcopy(PAPER)
    classes['orange']['count'] = 11
    classes['blue']['count'] = 2
    classes['green'] = {'color': [0.1, 0.8, 0.2, 1.0], 'count': 1, 'destination': 'pool_floor',
                        'route': 'carry'}
    classes['purple']['count'] = 2
    layout = layout_from_world(world(classes))
    assert len(layout.regions['pool_floor'].slots) >= 12
    colors = ['orange'] * 11 + ['blue'] * 2 + ['green', 'purple', 'purple']
    colors = [colors[(7 * k) % len(colors)] for k in range(len(colors))]    # (mixed)
    cell = ReleaseLog(layout, colors, gap=0.3)
    p = run(cell, limit=900.0)
    r = p.result
    assert r.status == 'completed', r
    assert r.total == 16 and r.delivered == 16 and r.failed == 0
    # (Two trips at least; a third when a stand has no drop spot left for a row's load.)
    assert 2 <= r.trips <= 3
    departing = kinds(cell, 'departing')
    loads = [int(e.detail.split()[0]) for e in departing]
    assert all(e.detail.endswith(f'trip {k + 1}') for k, e in enumerate(departing))
    assert len(departing) == r.trips
    assert sum(loads) == 14 and max(loads) <= 8
    # Each carried material was loaded while the youBot stood at home, between its trips.
    home = [e.time for e in kinds(cell, 'waiting_for_load')]
    assert len(home) == r.trips - 1
    loaded = [e.time for e in kinds(cell, 'loaded')]
    for left, back in zip(departing, home):
        assert not any(left.time < t < back for t in loaded)
    drops = [e.detail for e in kinds(cell, 'delivered') if e.detail.startswith('pool_floor')]
    assert len(drops) == 12 == len(set(drops))          # (each at a drop spot of its own)


def test_a_queue_that_would_overflow_the_belt_stops_it_and_the_result_counts_the_stops():
    """With the pick point 0.3 m from the end stop, the queue of materials waiting for the
    youBot's second trip reaches back to it: the belt stops until the queue moves up, and
    starts again; every material still arrives."""
    classes = copy.deepcopy(PAPER)
    classes['orange']['count'] = 12
    layout = layout_from_world(world(classes))
    cell = FakeCell(layout, ['orange'] * 12 + ['blue', 'purple'], gap=0.3)
    from coordinator.pipeline import Settings
    p = run(cell, Settings(pick_x=0.2), limit=900.0)
    r = p.result
    assert r.status == 'completed', r
    assert r.belt_stops >= 1
    stops = [e for e in kinds(cell, 'belt_stopped') if e.detail]
    assert len(stops) == r.belt_stops
    overflow = [e for e in stops if e.detail == 'the queue would overflow the belt']
    lifts = [e for e in stops if e.detail == 'a lift out of the end stop\'s queue']
    assert overflow and len(overflow) + len(lifts) == len(stops)


def test_the_belt_pauses_while_a_material_is_lifted_out_of_a_pressed_queue():
    """The belt drives the end stop's queue into the stop; a material lifted off its front
    dragged the ones pressed behind it up by their faces (13 oranges of 0.38 kg: they rose
    1 to 4 cm, fell back 2 cm aside and turned 12 degrees, and the next place hit them). The
    belt pauses from before the cup's contact until the lift is over, and only then: never
    for a material picked on the fly, or held with nothing pressed behind it."""
    classes = copy.deepcopy(PAPER)
    classes['orange']['count'] = 12
    layout = layout_from_world(world(classes))
    cell = FakeCell(layout, ['orange'] * 12 + ['blue', 'purple'], gap=0.3)
    from coordinator.pipeline import Settings
    p = run(cell, Settings(pick_x=0.2), limit=900.0)
    assert p.result.status == 'completed', p.result
    switched = [e for e in cell.events if e.kind in ('belt_stopped', 'belt_started')]
    pauses = [(e, next(s for s in switched if s.time > e.time and s.kind == 'belt_started'))
              for e in switched if e.detail == 'a lift out of the end stop\'s queue']
    assert pauses
    held = {e.material: float(e.detail.split()[2].rstrip(','))
            for e in kinds(cell, 'tracking') if 'held at the stop' in e.detail}
    lifted = {e.material: e.time for e in kinds(cell, 'picked')}
    for stop, start in pauses:
        m = next(k for k, c in held.items() if stop.time <= c <= start.time)
        assert stop.time <= held[m] - 0.3 and lifted[m] <= start.time
    # The paper's batch (picked on the fly, the purple alone at the stop): never.
    paper = FakeCell(layout_from_world(world(copy.deepcopy(PAPER))),
                     ['orange'] * 6 + ['blue', 'purple'])
    assert run(paper).result.belt_stops == 0


def test_a_set_down_swings_in_over_what_is_at_its_destination_already(monkeypatch):
    """Two 55 mm materials on one destination of each route: the arm carrying the second
    comes in over the first with what it holds SET_DOWN_CLEARANCE_M above it (a 5 cm rise
    over the drop swept the second youBot's blue through the first and pushed it off its
    slot)."""
    from coordinator.pipeline import model, pick_planner, transport
    classes = copy.deepcopy(PAPER)
    classes['purple'].update(count=2, size=0.06)
    classes['blue'].update(count=2, size=0.055)
    classes['orange'].update(count=4)
    layout = layout_from_world(world(classes))
    swings = {'zu12': [], 'youbot': []}
    carry_out = transport.Transport._carry_out
    place_way = pick_planner.PickPlanner.place_way

    def youbot(self, obs, m, over, drop, **kwargs):
        swings['youbot'].append((m.color, over[2] - drop[2]))
        return carry_out(self, obs, m, over, drop, **kwargs)

    def zu12(self, m, *args):
        way = place_way(self, m, *args)
        if not isinstance(way, str) and not way.onto_plate:
            # (The fake's joints are the tool's position: the last waypoint's, the release.)
            swings['zu12'].append((m.color, way.above[2] - way.waypoints[-1].q[2]))
        return way

    monkeypatch.setattr(transport.Transport, '_carry_out', youbot)
    monkeypatch.setattr(pick_planner.PickPlanner, 'place_way', zu12)
    cell = FakeCell(layout, ['orange', 'blue', 'purple', 'orange', 'blue', 'orange', 'purple',
                             'orange'])
    r = run(cell).result
    assert r.status == 'completed', r
    gap = model.Settings().timing.place_gap
    for arm, color, size in (('youbot', 'blue', 0.055), ('zu12', 'purple', 0.06)):
        rises = [h for c, h in swings[arm] if c == color]
        assert len(rises) == 2
        assert rises[1] >= size + model.SET_DOWN_CLEARANCE_M - gap - 1e-9


def test_the_cup_rises_straight_up_from_a_place_before_it_swings_away(monkeypatch):
    """After every release on the ground target, the Zu 12's next motion (to the next pick, to
    wait, or home) passes first through the point straight above the place (over what stands
    there), and only then swings away: a joint motion from the release straight towards home
    swept two materials off their slots beside it. (The fake's joints are the cup's position,
    so the sweep itself shows only on the real arm: this holds the plan to the way up.)"""
    from coordinator.pipeline import robots
    classes = copy.deepcopy(PAPER)
    classes['purple']['count'] = 3
    classes['orange']['count'] = 2
    layout = layout_from_world(world(classes))
    firsts = []
    from_release = robots.CupPlace.from_release

    def record(self, waypoints, edge=None):
        way, wait = from_release(self, waypoints, edge)
        if self.at_release and not self.onto_plate:
            firsts.append((way[0], self.above_q, self.above))
        return way, wait

    monkeypatch.setattr(robots.CupPlace, 'from_release', record)
    # (The last purple is the last material: from its place the arm goes home.)
    cell = FakeCell(layout, ['purple', 'orange', 'purple', 'blue', 'orange', 'purple'])
    r = run(cell).result
    assert r.status == 'completed', r
    assert len(firsts) >= 3
    for first, above_q, above in firsts:
        assert np.allclose(first.q, above_q)
        assert above[2] >= layout.regions['ground_target'].top + 0.05 + 0.07 - 1e-9


def test_a_plate_slot_whose_material_the_youbot_failed_to_unload_is_not_used_again():
    """A material the youBot could not take off its plate stays there: the Zu 12 does not
    set the next trip's material down on it (it did, and its arm hit it at 2.3 times a
    joint's speed limit)."""
    from coordinator.pipeline import Material, Pipeline, Settings
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    run_ = Pipeline(layout, FakeCell(layout, []), Settings())
    stuck = Material(1, 'orange', np.zeros(3), 0.0, 3, status='failed', slot=0, plate='youbot',
                     failure='unload: no motion off the plate', left_on_plate=True)
    gone = Material(2, 'orange', np.zeros(3), 0.0, 3, status='failed', slot=2,
                    failure='dropped on the way to its place')
    new = Material(3, 'orange', np.zeros(3), 0.0, 3, plate='youbot')
    run_.materials.update({1: stuck, 2: gone, 3: new})
    room = run_.loader.room
    assert 0 in room.plate_taken('youbot') and 2 not in room.plate_taken('youbot')
    assert 0 not in room.plate_slots(new, 'youbot') and 2 in room.plate_slots(new, 'youbot')
    # And the youBot's lifts keep clear of it.
    assert (*layout.plate_slots[0], 0.05) in run_.transport.planner.others(new)


def test_a_pick_whose_joint_path_is_out_of_the_limits_meets_the_material_further_on(
        monkeypatch):
    """The IK can change branch along a stretch of the track, and the planner refuses the
    joints' path there: the pick is planned to meet the material a little later, instead of
    giving it up (a 47 mm orange was, "joint 3 acceleration -320 is beyond its limit")."""
    from controllers.time_optimal import PlanError
    from coordinator.pipeline import robots
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    refused = []
    plan = robots.CupPlace.plan

    def refuse_once(self, obs, waypoints, start=None, edge=None):
        if any(w.direct for w in waypoints) and not refused:       # (a pick's path)
            refused.append(waypoints[0].at)
            raise PlanError('waypoint 5: joint 3 acceleration -320.373 is beyond its limit')
        return plan(self, obs, waypoints, start, edge)

    monkeypatch.setattr(robots.CupPlace, 'plan', refuse_once)
    cell = FakeCell(layout, ['orange', 'purple', 'orange', 'blue', 'orange', 'orange',
                             'orange', 'orange'])
    r = run(cell).result
    assert refused
    assert r.status == 'completed', r
    assert r.grasp_attempts == r.grasp_successes == 15


def test_a_pick_path_across_an_elbow_flip_is_solved_on_one_branch():
    """Near the Zu 12's base the IK, seeded with the sample before, flips the elbow between
    two samples of a pick's path (the planner then refuses it: "joint 3 acceleration -320"):
    the path is solved again from its end, on the branch the end is on."""
    from types import SimpleNamespace

    from cell_layout import pick_geometry
    from coordinator.pipeline import pick_planner

    def solve_path(points, seed):
        """Two branches: 'up' (joint 1 at +1) reaches x < 0 only; 'down' (-1) everywhere.
        Each point takes the seed's branch where it can."""
        qs = []
        for p in points:
            up = seed[1] > 0 and p[0] < 0.0
            seed = np.array([p[0], 1.0 if up else -1.0, 0.0, 0.0, 0.0, 0.0])
            qs.append(seed)
        return qs

    from coordinator.pipeline import Settings
    arm = SimpleNamespace(name='zu12', solve_path=solve_path)
    zu12 = pick_planner.PickPlanner(arm, None, None, None, None, Settings(), None)
    path = [(k * 0.05, np.array([-0.1 + 0.02 * k, 0.75, 0.45])) for k in range(10)]
    qs = zu12.solve_along(path, np.array([0.1, 0.75, 0.5]), np.array([0.0, 1.0, 0, 0, 0, 0]))
    assert qs is not None and len(qs) == 11
    assert all(q[1] == -1.0 for q in qs)               # all on the branch that reaches
    assert pick_geometry.continuous(qs)
    # A path that one branch covers is kept as solved.
    short = path[:4]
    qs = zu12.solve_along(short, np.array([-0.05, 0.75, 0.5]), np.array([0, 1.0, 0, 0, 0, 0]))
    assert all(q[1] == 1.0 for q in qs)


@pytest.mark.parametrize('size', [0.04, 0.05, 0.055, 0.06])
def test_every_pool_drop_is_reached_from_every_slot_of_its_stands_row(size):
    """The drops the layout gives each stand are the ones the transport's planner reaches: a
    drop is used by whichever material of the stand's row unloads next, so from each slot of
    that row, the others full of materials as tall, the way to each drop is found (with the
    real youBot IK), and its lift off the plate (the timed joint motion, as the arm lifts it
    while the base drives) keeps the material clear of its neighbours. The layout checked its
    drops more loosely than the planner went: 13 oranges of 52 mm found no way to the stand's
    last drops. And the lift to a drop reached at another tilt rose its last 6 cm in one joint
    step, which swung a cube 2 cm sideways: from slot 2 of the left row, between two others, no
    lift to the stand's third drop kept clear of them, and the orange was left on the plate."""
    from test_pipeline import _YoubotIK

    from coordinator.pipeline import Material, Pipeline, Settings
    classes = copy.deepcopy(PAPER)
    classes['orange'].update(count=13, size=size)
    classes['blue'].update(size=min(size, 0.05))
    layout = layout_from_world(world(classes))
    assert len(layout.regions['pool_floor'].slots) >= 13
    run_ = Pipeline(layout, _YoubotIK(), Settings())
    tr = run_.transport
    for stand in layout.stands:
        row = [k for k, s in enumerate(layout.plate_slots) if layout.slot_row(k) == stand.row]
        for k in row:
            run_.materials.clear()
            run_.materials.update({
                10 + j: Material(10 + j, 'orange', np.zeros(3), 0.0, 3, status='on_plate',
                                 slot=j, size=size) for j in range(len(layout.plate_slots))})
            m = run_.materials[10 + k]
            for d in range(len(stand.drops)):
                run_.book._dropped = {stand.name: set(range(len(stand.drops))) - {d}}
                # (Standing, the planner may slide the base along the stand's line.)
                path = tr.planner.unload_path(m, stand.pose, np.zeros(5), slide=True)
                assert path is not None and path.place == d, (stand.name, k, d)
                tr.planner.lift_from(path.contact, m, path)       # (a PlanError if not clear)


def test_after_a_release_the_youbot_waits_for_its_arm_to_come_to_rest():
    """An arm that sagged under a heavy material springs back as it lets go: a motion planned
    from where it is meanwhile started 0.11-0.16 rad off, the controller refused it and the
    next unload failed. The next motion waits until the arm is still (up to
    SPRING_BACK_WAIT_S)."""
    from coordinator.pipeline import Material, Pipeline, Settings
    from coordinator.pipeline.model import RELEASE_HOLD_S, SPRING_BACK_WAIT_S, TransportState
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    run_ = Pipeline(layout, FakeCell(layout, []), Settings())
    tr = run_.transport
    went_on = []
    tr._next_unload = lambda obs: went_on.append(obs.now)
    pose = layout.youbot_home

    def release_at(now, speed):
        tr.queue = [Material(1, 'orange', np.zeros(3), 0.0, 3, status='delivered')]
        tr.state = TransportState.CARRY                 # (it has just let go at the drop)
        tr.enter(TransportState.RELEASE, 0.0, RELEASE_HOLD_S)
        went_on.clear()
        tr._release(observation(now, np.zeros(6), np.zeros(5), pose,
                                youbot_dq=np.full(5, speed)))
        return bool(went_on)

    assert not release_at(0.05, 0.0)                     # (the hold first)
    assert release_at(0.2, 0.0)                          # still: on at once
    assert not release_at(0.2, 0.6)                      # springing back: it waits
    assert release_at(RELEASE_HOLD_S + SPRING_BACK_WAIT_S + 0.05, 0.6)   # but not for ever


def test_an_unload_that_stalled_short_of_its_drop_is_a_failure_not_a_delivery():
    """A 0.44 kg blue's unload stalled 2 cm over its plate slot; the youBot let go and reported
    it set down on the platform. Stalled with the gripper more than DROP_REACH_TOLERANCE_M
    across from its drop, it is a failure that names how far, and the material keeps its plate
    slot; stalled near its drop (a sagging shoulder, 2 cm off over the pool), a delivery."""
    from test_pipeline import _YoubotIK

    from cell_layout.unload_geometry import DROP_REACH_TOLERANCE_M, short_of
    from coordinator.pipeline import Material, Pipeline, Settings
    from coordinator.pipeline.model import MaterialStatus, TransportState
    class Ports(_YoubotIK):
        def grip(self, arm, on):
            return True, ''

    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    run_ = Pipeline(layout, Ports(), Settings())
    tr = run_.transport
    tr._next_unload = lambda obs: None
    tr.arrival = lambda obs: False                          # (the motion's end passed)
    for where, delivered in (('slot', False), ('drop', True)):
        m = Material(1, 'blue', np.zeros(3), 0.0, 3, status='on_plate', slot=0)
        run_.materials.clear()
        run_.materials[1] = m
        stand = layout.stand_for('blue', 0)
        path = tr.planner.unload_path(m, stand.pose, np.zeros(5))
        tr._carry, tr.queue, tr._drop_pending = path, [m], False
        tr.state = TransportState.CARRY                     # (carrying it to its drop)
        q = path.contact if where == 'slot' else path.drop
        obs = observation(10.0, np.zeros(6), q, stand.pose, youbot_holding=True)
        assert (short_of(q, path.drop) > DROP_REACH_TOLERANCE_M) is not delivered
        tr._carry_to_drop(obs)
        assert (m.status is MaterialStatus.DELIVERED) is delivered, m
        assert m.left_on_plate is not delivered
        if not delivered:
            assert m.failure.startswith('unload: the arm stalled')
            assert 'short of the drop' in m.failure
            assert 'needs' not in m.failure           # (0.1 kg: held, it stalled otherwise)


def test_an_unload_stalled_under_a_load_the_arm_cannot_hold_names_the_joint_and_its_torque():
    from test_pipeline import _YoubotIK

    from cell_layout.reach import youbot_hold_need
    from coordinator.pipeline import Material, Pipeline, Settings

    class Ports(_YoubotIK):
        def grip(self, arm, on):
            return True, ''

    classes = copy.deepcopy(PAPER)
    classes['orange'].update(mass=0.5)
    layout = layout_from_world(world(classes))
    run_ = Pipeline(layout, Ports(), Settings())
    tr = run_.transport
    tr._next_unload = lambda obs: None
    tr.arrival = lambda obs: False
    m = Material(1, 'orange', np.zeros(3), 0.0, 3, status='on_plate', slot=0)
    run_.materials[1] = m
    stand = layout.stand_for('orange', 0)
    path = tr.planner.unload_path(m, stand.pose, np.zeros(5))
    tr._carry, tr.queue, tr._drop_pending = path, [m], False
    # Stalled with the arm stretched out flat (the shoulder at its forward limit).
    q = np.array([0.0, 1.5, 0.0, 0.0, 0.0])
    joint, torque, effort = youbot_hold_need(q, 0.5)
    assert torque > 0.95 * effort
    tr._carry_to_drop(observation(10.0, np.zeros(6), q, stand.pose, youbot_holding=True))
    assert m.left_on_plate
    assert (f'; holding 0.5 kg there, {joint} needs {torque:.2f} N m at rest (its motor: '
            f'{effort:g} N m)') in m.failure
    stalls = [e for e in run_.events if e.kind.value == 'arm_stalled']
    assert stalls and f'{joint} needs {torque:.2f} N m' in stalls[-1].detail


def test_a_lift_out_of_the_end_stops_queue_keeps_to_the_straight_line_up():
    """Lifted off the end stop with another material right behind it, the cup rises straight
    up (real Zu 12 IK): the joints' own way from the dwell to the lift point bowed 1.8 cm
    upstream as it began, into the material behind, and lifted the whole queue with it. Alone
    at the stop, or moving on the belt, the lift is one motion to the lift point as before."""
    from types import SimpleNamespace

    from test_pipeline import Zu12IK

    from controllers.pick_place import PickTiming
    from controllers.transforms import quaternion_to_matrix
    from coordinator.pipeline import Material, Pipeline, Settings
    from coordinator.pipeline.model import DOWN

    layout = layout_from_world(world(copy.deepcopy(PAPER)))      # (the Zu 12 at the origin)
    ik = Zu12IK()
    run_ = Pipeline(layout, ik, Settings())
    zu12 = run_.loader.planner
    m = Material(1, 'purple', np.array([0.675, 0.75, 0.425]), 0.0, 3, size=0.05)
    on = np.array([0.675, 0.75, 0.4 + 0.05 + 0.001])
    zu12.lift_point = on + np.array([0.0, 0.0, 0.07])
    ready = np.array([1.201, 1.436, -1.222, 1.357, 1.571, -0.37])    # (the world's)
    q_on, q_lift = run_.loader_arm.solve_path([on, zu12.lift_point], ready)
    pick = SimpleNamespace(timing=PickTiming(lift_height=0.07), contact=1.0)
    for crowded in (True, False):
        zu12.belt = SimpleNamespace(held=lambda m: True, held_by=lambda m, t: True,
                                    crowded=lambda m, t, crowded=crowded: crowded)
        way = zu12.lift_way(m, pick, on, q_on, 1.0, q_lift)
        assert np.allclose(way[-1].q, q_lift, atol=1e-9)
        if not crowded:
            assert len(way) == 1
            continue
        assert len(way) > 5 and all(w.direct for w in way)
        tips = [ik.kin.fk(w.q)[:3, 3] for w in way]
        assert max(float(np.linalg.norm(t[:2] - on[:2])) for t in tips) < 1e-3
        assert all(b[2] >= a[2] - 1e-6 for a, b in zip(tips, tips[1:]))
        assert np.allclose(ik.kin.fk(way[-1].q)[:3, :3], quaternion_to_matrix(DOWN),
                           atol=1e-6)
