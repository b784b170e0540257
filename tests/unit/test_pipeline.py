"""The coordinator's state machine against a fake cell: the whole run and every failure path."""
import dataclasses
import math
import re
from typing import Callable, Dict, List, Optional

import numpy as np
import pytest

from cell_layout.layout import CellLayout, LayoutError
from cell_layout.world_layout import layout_from_world
from controllers.belt_speed import WINDOW_S
from controllers.conveyor import Item, advance
from controllers.time_optimal import Waypoint
from coordinator.pipeline import (
    YOUBOT_CARRY_Q,
    ArmReading,
    BaseReading,
    Detection,
    LoaderState,
    NodeTimeout,
    Observation,
    Pipeline,
    Settings,
    youbot_tool_quaternion,
)
from world_description.resources import resolve_resource
from world_description.world_config import load_world

DT = 1.0 / 30.0
CAMERA_X = (-1.0, -0.1)          # the fake camera sees this stretch of the belt


def cell_layout() -> CellLayout:
    world = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
    return layout_from_world(world)


class FakeCell:
    """Kinematic stand-in for the simulator, vision and kinematics nodes. Its IK answers a
    tool position with a joint vector whose first three values are that position, so the Zu 12
    arm, which follows its trajectories, shows where its cup is: the cup seals on a material
    when it is on that material's top face (a tracking pick must really meet it there)."""

    def __init__(self, layout: CellLayout, colors: List[str], gap: float = 0.35,
                 grasp_failures: Dict[int, int] = None, unreachable=lambda arm, p: False,
                 stall: bool = False, blind: bool = False, timeout_on: str = '',
                 drop_on_transfer: int = -1, drive_works: bool = True,
                 belt_latency: float = 0.0, send_lag: float = 0.0,
                 taken_late: float = 0.0, held_in_view: bool = False,
                 solve_cost: float = 0.0, refuse_picks: int = 0,
                 base_loop: bool = False,
                 belt_drift: Callable[[float], float] = lambda t: 1.0,
                 encoder: float = 0.0) -> None:
        self.layout = layout
        self.now = 0.0
        self.belt_speed = 0.0
        # The belt runs at its set speed times this (at the simulated time): it drifts.
        self.belt_drift = belt_drift
        # The conveyor drive's encoder: its resolution (0: none), and the belt's travel.
        self.encoder, self.travel, self.next_count = encoder, 0.0, 0.0
        # Materials: id -> [x, y, colour, on_belt]
        self.materials = {i + 1: [-1.15 - i * gap, layout.belt_y, c, True]
                          for i, c in enumerate(colors)}
        self.hits: Dict[int, int] = {}
        # The arms: the Zu 12 (its name in the fake) and each youBot, by the layout's names.
        self.bases = [r.name for r in layout.transports]
        arms = {'zu12': 6, **{b: 5 for b in self.bases}}
        self.q = {a: np.zeros(n) for a, n in arms.items()}
        self.goal = {a: (0.0, np.zeros(n)) for a, n in arms.items()}
        self.plans = {a: None for a in arms}            # (times, positions) as followed
        self.armed = {a: False for a in arms}
        self.sealed = {a: False for a in arms}          # a seal was tried since arming
        self.holding = {a: False for a in arms}
        # Each base where it starts (its park in a fleet), and its pose at every step.
        self.poses = {b: np.array(layout.park(b), float) for b in self.bases}
        self.paths: Dict[str, List[np.ndarray]] = {b: [] for b in self.bases}
        self.twists = {b: np.zeros(3) for b in self.bases}
        self.followers = {b: None for b in self.bases}
        self.grasp_failures = dict(grasp_failures or {})
        self.unreachable, self.stall, self.blind = unreachable, stall, blind
        self.timeout_on, self.drop_on_transfer = timeout_on, drop_on_transfer
        self.drive_works = drive_works
        # A belt command takes effect this late (real time), and the port does not say so.
        self.belt_latency = belt_latency
        self._belt_pending: List[tuple] = []
        # The real-time port: the plan took this much longer than its allowance, so every
        # motion starts this much later than planned.
        self.send_lag = send_lag
        # Real time: every IK call takes this much of the simulator's time, which runs on
        # while the coordinator plans (``busy``: spent since the last observation). A motion
        # due to start sooner than plan_latency after it is sent starts that much later.
        self.solve_cost, self.busy = solve_cost, 0.0
        # The simulator refuses this many of the Zu 12's pick motions (taken in too late, in
        # real time), and the arm holds where it is.
        self.refuse_picks = refuse_picks
        # The real-time port's base controller: it runs the drive's follower on every step,
        # held-up decisions or not. Without it the base runs on the last tick's command.
        self.base_loop = base_loop
        self.drive_errors: List[float] = []       # the base's distance from its path's dummy
        # The simulator took each motion in this late: at the end the port reported, the arm is
        # near its goal but still moving, for this long.
        self.taken_late = taken_late
        self.moving = {a: False for a in arms}
        self.held_in_view = held_in_view
        self.grips_while_moving: List[tuple] = []
        self.let_go_at = np.full(3, np.inf)           # where the Zu 12's cup last let go
        self.regrips: List[float] = []
        self.trajectories: List[tuple] = []
        self.replaced: List[tuple] = []     # youBot motions sent before the last one ended
        self.final_x: Dict[int, float] = {}          # where each material was when lifted
        self.events = []
        self.belt_calls: List[float] = []
        self.drive_calls: List[tuple] = []
        self.continuations: List[tuple] = []
        self.pipeline: Pipeline = None

    @property
    def pose(self) -> np.ndarray:
        """The first youBot's pose (the paper's only one)."""
        return self.poses[self.bases[0]]

    @property
    def path(self) -> List[np.ndarray]:
        return self.paths[self.bases[0]]

    # --- ports ---
    def solve(self, arm, position, orientation, frame, seed):
        self.busy += self.solve_cost
        if self.timeout_on == 'solve':
            raise NodeTimeout('/zu12/solve_ik did not answer')
        if self.unreachable(arm, position):
            return None, 'out of reach'
        n = 6 if arm == 'zu12' else 5
        q = np.zeros(n)
        q[:3] = position
        return q, ''

    def trajectory(self, arm, points, start, continuing=False):
        if continuing:
            # Goes on from the running motion: its start lies in the past or now, its first
            # points are that motion's samples, and it is sent as it is.
            assert start <= self.now and points[0][0] > self.now
            self.continuations.append((arm, self.now, start, points))
            self.goal[arm] = (points[-1][0], np.array(points[-1][1]))
            self.plans[arm] = (np.array([p[0] for p in points]),
                               np.array([p[1] for p in points]))
            self.trajectories.append((arm, self.now, points))
            return 0.0
        assert start >= self.now
        # The plan took send_lag longer than planned for: a motion due to start before now +
        # send_lag starts that much later, whole.
        current = self.pipeline.loader.current
        if (arm == 'zu12' and self.refuse_picks and current is not None
                and current.status == 'picking'):
            self.refuse_picks -= 1
            self.trajectories.append((arm, self.now, 'refused'))
            return 0.0
        sent = self.now + self.busy
        if arm == 'youbot' and sent < self.goal[arm][0]:
            self.replaced.append((self.now, self.goal[arm][0]))
        lag = max(0.0, sent + self.send_lag - start)
        if self.solve_cost:
            lag = max(lag, sent + self.pipeline.s.plan_latency - start)
        self.goal[arm] = (points[-1][0] + lag, np.array(points[-1][1]))
        self.plans[arm] = (np.array([p[0] for p in points]) + lag,
                           np.array([p[1] for p in points]))
        self.trajectories.append((arm, self.now, points))
        return lag

    def grip(self, arm, on):
        if self.timeout_on == 'grip':
            raise NodeTimeout('/zu12/suction did not answer')
        if self.moving[arm]:
            self.grips_while_moving.append((arm, on, self.now))
        self.armed[arm], self.sealed[arm] = on, False
        if not on:
            if arm == 'zu12' and self.holding[arm]:
                self.let_go_at = self.q[arm][:3].copy()
            self.holding[arm] = False
        elif arm == 'zu12' and np.linalg.norm(self.q[arm][:3] - self.let_go_at) < 0.01:
            # Switched on again where it let go: it seals on what it just set down.
            self.sealed[arm], self.holding[arm] = True, True
            self.regrips.append(self.now)
        return True, 'ok'

    def belt(self, speed):
        self.belt_calls.append(speed)
        if self.belt_latency > 0.0:
            self._belt_pending.append((self.now + self.belt_latency, speed))
        else:
            self.belt_speed = speed

    def drive(self, robot, vx, vy, wz):
        self.drive_calls.append((vx, vy, wz))
        self.twists[robot] = np.array([vx, vy, wz]) if self.drive_works else np.zeros(3)

    def follow(self, robot, follower):
        self.followers[robot] = follower
        return follower is not None and self.base_loop

    def event(self, e):
        self.events.append(e)

    # --- the world ---
    def step(self) -> Observation:
        self.now += DT
        while self._belt_pending and self._belt_pending[0][0] <= self.now:
            self.belt_speed = self._belt_pending.pop(0)[1]
        # The belt carries what lies on it; its end stop (if any) holds what reaches it.
        on = [m for m in self.materials.values() if m[3]]
        size, stop = self.layout.material_size, (self.layout.belt_end_x
                                                 if self.layout.end_stop else math.inf)
        items = [Item(m[0], m[1] - self.layout.belt_y, size, size) for m in on]
        for m, x in zip(on, advance(items, stop, self.belt_speed * self.belt_drift(self.now)
                                    * DT)):
            m[0] = x
        self.travel += self.belt_speed * self.belt_drift(self.now) * DT
        for arm in self.q:
            t_end, goal = self.goal[arm]
            if arm == 'zu12' and self.plans[arm] is not None and not self.stall:
                # The Zu 12 follows its trajectory (from where it was when it got it).
                times, qs = self.plans[arm]
                if self.now < times[0]:
                    pass
                elif self.now >= times[-1]:
                    self.q[arm] = qs[-1].copy()
                else:
                    k = int(np.searchsorted(times, self.now))
                    f = (self.now - times[k - 1]) / (times[k] - times[k - 1])
                    self.q[arm] = qs[k - 1] + f * (qs[k] - qs[k - 1])
            elif self.now >= t_end and not self.stall:
                self.q[arm] = goal.copy()
            self.moving[arm] = t_end <= self.now < t_end + self.taken_late
            t_end += self.taken_late
            if not self.armed[arm] or self.sealed[arm] or self.stall:
                continue
            if arm == 'zu12':
                # An armed cup seals when it is on a material's top face.
                key = self._under_the_cup()
            else:
                # The youBot's gripper closes once the arm is at rest at its goal (on the part).
                key = self._material_for(arm) if self.now >= t_end else None
            if key is None:
                continue
            self.sealed[arm] = True
            if self.grasp_failures.get(key, 0) > 0:
                self.grasp_failures[key] -= 1
            else:
                self.holding[arm] = True
                if arm == 'zu12' and key in self.materials:
                    self.materials[key][3] = False
                    self.final_x[key] = self.materials[key][0]
        p = self.pipeline
        held = p.loader.current
        if (self.drop_on_transfer >= 0 and held is not None
                and held.id == self.drop_on_transfer and p.loader.state is LoaderState.PLACE):
            self.holding['zu12'] = False
        velocities = {b: self._move_base(b) for b in self.bases}
        dets = []
        if not self.blind:
            for i, (x, y, color, on_belt) in self.materials.items():
                if on_belt and CAMERA_X[0] <= x <= CAMERA_X[1]:
                    self.hits[i] = self.hits.get(i, 0) + 1
                    dets.append(Detection(i, color, np.array([x, y, 0.425]), self.now,
                                          self.hits[i]))
            held = self._material_for('zu12') if self.holding['zu12'] else -1
            # Where the cup is (the fake's joint vector is the tool position).
            tool = self.q['zu12'][:3]
            if self.held_in_view and held > 0 and CAMERA_X[0] <= tool[0] <= CAMERA_X[1]:
                # The camera sees the held material beside the belt (a track of its own).
                self.hits[100 + held] = self.hits.get(100 + held, 0) + 1
                dets.append(Detection(100 + held, self.materials[held][2],
                                      np.array([tool[0], tool[1], 0.425]), self.now,
                                      self.hits[100 + held]))
        arms = {arm: ArmReading(self.q[arm].copy(), np.full(len(self.q[arm]),
                                                            0.5 if self.moving[arm] else 0.0),
                                self.holding[arm], self.armed[arm]) for arm in self.q}
        # (The drive reports at 10 Hz, as the simulator's does by default.)
        counts = []
        if self.encoder and self.now >= self.next_count - 1e-9:
            counts = [(self.now, math.floor(self.travel / self.encoder) * self.encoder)]
            self.next_count = math.floor(self.now * 10.0 + 1e-6) / 10.0 + 0.1
        return Observation(self.now, arms, {b: BaseReading(tuple(self.poses[b]), velocities[b])
                                            for b in self.bases}, dets, counts)

    def _move_base(self, base):
        """One step of a base on its twist (the follower's, with ``base_loop``)."""
        pose = self.poses[base]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        vx, vy, wz = self.twists[base]
        world_v = (c * vx - s * vy, s * vx + c * vy, wz)
        follower = self.followers[base]
        if follower is not None:
            status = follower.update(self.now, tuple(pose), world_v[:2], wz)
            self.drive_errors.append(status.position_error)
            if self.base_loop:
                self.drive(base, *status.command)
                vx, vy, wz = self.twists[base]
                world_v = (c * vx - s * vy, s * vx + c * vy, wz)
        pose += np.array(world_v) * DT
        self.paths[base].append(pose.copy())
        return world_v

    def _under_the_cup(self):
        tool = self.q['zu12'][:3]
        top = self.layout.belt_top + self.layout.material_size
        for i, (x, y, _, on_belt) in self.materials.items():
            if (on_belt and abs(tool[0] - x) < 0.01 and abs(tool[1] - y) < 0.01
                    and tool[2] - top < 0.002):
                return i
        return None

    def _material_for(self, arm):
        p = self.pipeline
        current = (p.loader.current if arm == 'zu12' else
                   next(t for t in p.transports if t.robot == arm).current)
        return current.id if current else -1


PAPER = ['orange', 'purple', 'orange', 'blue', 'orange', 'orange', 'orange', 'orange']


def run(cell: FakeCell, settings: Optional[Settings] = None, limit: float = 600.0,
        lag=None) -> Pipeline:
    """Tick the pipeline on every observation; ``lag(now)``: how many further observations
    the coordinator misses after a tick (it lags the simulator)."""
    pipeline = Pipeline(cell.layout, cell, settings or Settings(), 0.0)
    cell.pipeline = pipeline
    # (The fake cell's joints are the tool's position, not the Zu 12's: the way on from a lift
    # point, which is checked against the belt by the arm's forward kinematics, has nothing to
    # be checked against here; test_queue_pick.py checks it with the Zu 12's.)
    planner = pipeline.loader.planner
    planner.clear_of_belt = lambda m, q, way, plan, lifted=0.0: planner.clear_way(
        plan(way.waypoints), way, plan)
    obs = cell.step()
    while not pipeline.finished:
        pipeline.tick(obs)
        assert cell.now < limit, 'the run did not end'
        for _ in range(lag(cell.now) if lag else 0):
            cell.step()
        while cell.busy > 0.0:          # the simulator ran on while the coordinator planned
            cell.step()
            cell.busy -= DT
        obs = cell.step()
    return pipeline


def observation(now, zu12_q, youbot_q, pose, youbot_dq=None, youbot_holding=False):
    """An observation of the paper's cell, by hand."""
    return Observation(now, {'zu12': ArmReading(zu12_q),
                             'youbot': ArmReading(youbot_q, youbot_dq, youbot_holding)},
                       {'youbot': BaseReading(tuple(pose))})


def kinds(cell: FakeCell, kind: str):
    return [e for e in cell.events if e.kind == kind]


def test_the_whole_run_delivers_every_material_and_both_robots_return():
    layout = cell_layout()
    cell = FakeCell(layout, PAPER)
    p = run(cell)
    r = p.result
    assert r.status == 'completed', r
    assert (r.total, r.identified, r.picked, r.delivered) == (8, 8, 8, 8)
    assert r.grasp_attempts == r.grasp_successes == 15          # 8 picks + 7 unloads
    assert len(kinds(cell, 'placed')) == 1 and kinds(cell, 'placed')[0].color == 'purple'
    assert len(kinds(cell, 'loaded')) == 7
    delivered = kinds(cell, 'delivered')
    assert sorted(e.detail.split(' drop ')[0] for e in delivered) == (['pool_floor'] * 6
                                                                   + ['pool_platform slot 0'])
    # The youBot left only with its whole load, and is home again; the belt is stopped.
    first_delivery = min(e.time for e in delivered)
    assert first_delivery > max(e.time for e in kinds(cell, 'loaded'))
    assert np.hypot(*(cell.pose[:2] - layout.youbot_home[:2])) < 0.02
    assert cell.belt_calls[-1] == 0.0 and cell.drive_calls[-1] == (0.0, 0.0, 0.0)
    assert np.allclose(cell.q['zu12'], 0.0) and np.allclose(cell.q['youbot'], 0.0)
    assert r.completion_time == pytest.approx(cell.now - DT, abs=1e-9)
    # The cup is switched on for the next pick only once it has risen from the last place.
    assert cell.regrips == []
    # The youBot's arm rises to its carry pose as the base sets off home, and goes back to its
    # start pose only there (a folded arm reaches down in front of the base).
    transport = [e.detail for e in cell.events if e.kind == 'state' and e.robot == 'transport']
    assert transport[-3:] == ['drive', 'fold', 'done']
    home = max(e.time for e in kinds(cell, 'driving'))
    after = [t for arm, t, _ in cell.trajectories if arm == 'youbot' and t >= home - 1e-9]
    assert after[0] == pytest.approx(home, abs=DT)           # up, as the base sets off
    assert after[1] >= max(e.time for e in kinds(cell, 'arrived')) - 1e-9     # at home


def test_each_material_keeps_the_detection_that_confirmed_it_as_the_vision_reported_it():
    """Identification is the vision's: the colour and the position of the frame that confirmed
    a material, at that frame's stamp. The material's ``position`` is carried on by the belt
    model, which in real time can be off (a belt that ran before the coordinator started); the
    score must not depend on it."""
    cell = FakeCell(cell_layout(), PAPER)
    p = run(cell)
    seen = {e.material: e.time for e in kinds(cell, 'seen')}
    assert set(seen) == set(p.materials) and len(seen) == 8
    for m in p.materials.values():
        d = m.detection
        assert d is not None and d.id == m.id and d.color == m.color
        assert d.hits >= Settings().confirm_hits and d.stamp <= seen[m.id]
        assert CAMERA_X[0] <= d.position[0] <= CAMERA_X[1]


@pytest.mark.parametrize('ran_before', [False, True])
def test_a_belt_running_before_the_start_carries_what_was_seen_before_it(ran_before):
    """A real-time simulator started with its belt on runs it before the coordinator begins.
    A frame from before the start shows a material that has ridden on since, and the belt model
    must say so (it assumed a stopped belt: the material was placed short of where it was)."""
    layout = cell_layout()
    cell = FakeCell(layout, PAPER, blind=True)
    pipeline = Pipeline(layout, cell, Settings(), 5.0, belt_ran_before=ran_before)
    cell.pipeline, cell.now = pipeline, 5.0
    obs = dataclasses.replace(cell.step(), detections=[
        Detection(1, 'orange', np.array([-0.8, layout.belt_y, 0.425]), 4.0, 9)])
    pipeline.tick(obs)
    ridden = layout.belt_speed * (obs.now - 4.0) if ran_before else 0.0
    assert pipeline.materials[1].position[0] == pytest.approx(-0.8 + ridden)
    assert pipeline.materials[1].detection.position[0] == -0.8


def test_oranges_leave_a_slot_of_the_platforms_row_for_the_blue_still_to_come():
    layout = cell_layout()
    platform = layout.stand_for('blue', 0)
    row = [k for k in layout.slot_order('blue') if layout.stand_for('orange', k) is platform]
    assert len(row) == 4 and 'pool_platform' in platform.serves
    # Three oranges in the platform's row: a fourth goes to the other row, the blue still to
    # come gets the last slot of the platform's row (four oranges ahead of it took the whole
    # row, and the blue had to be unloaded from the other row, the long way round).
    taken = {k: 'orange' for k in row[:3]}
    assert row[3] not in layout.free_slots('orange', taken)
    assert layout.stand_for('orange', layout.free_slots('orange', taken)[0]) is not platform
    assert layout.free_slots('blue', taken)[0] == row[3]
    # The blue on the plate (anywhere): nothing is kept back any more.
    assert layout.free_slots('orange', {**taken, 7: 'blue'})[0] == row[3]
    # Before that, oranges fill the platform's row first, as before.
    assert layout.free_slots('orange', {})[:3] == row[:3]
    # A batch without blue keeps nothing back.
    no_blue = dataclasses.replace(layout, manifest={'purple': 1, 'orange': 7})
    assert no_blue.free_slots('orange', taken)[0] == row[3]


def test_the_cells_youbot_waits_with_its_arm_in_the_carry_pose():
    # It starts (and so ends) the run as it drives: no unfolding on the way out, no folding at
    # home. Upright, the arm stands in front of the load plate, clear of the Zu 12's places.
    world = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
    start = dict(world.robot('youbot').initial_joint_positions)
    arm = [start.get(f'arm_joint_{k}', 0.0) for k in range(1, 6)]
    assert np.allclose(arm, YOUBOT_CARRY_Q)


def _footprint_clearance(pose, box_center, box_size, half=(0.285, 0.18)) -> float:
    """How far the youBot's base (its box's half length and width, and its wheels, at
    ``pose``) is from an upright box on the floor (centre x, y; size x, y), sampled every 5 mm
    along the box's outline and at the wheels' corners (negative: inside it). The wheels
    stand out 29 mm beyond the box's sides: each a cylinder (radius 47.5 mm, 50 mm long) at
    (+-0.228, +-0.158) m, its axis turned 45 degrees (the description's)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    out = []
    for u in np.linspace(-1.0, 1.0, int(2 * half[0] / 0.005) + 1):
        for v in (-1.0, 1.0):
            out.append((u * half[0], v * half[1]))
    for v in np.linspace(-1.0, 1.0, int(2 * half[1] / 0.005) + 1):
        for u in (-1.0, 1.0):
            out.append((u * half[0], v * half[1]))
    for wx, wy in ((0.228, 0.158), (0.228, -0.158), (-0.228, -0.158), (-0.228, 0.158)):
        turn = -math.pi / 4 if wx * wy > 0 else math.pi / 4
        wc, ws = math.cos(turn), math.sin(turn)
        for a, b in ((0.0475, 0.025), (0.0475, -0.025), (-0.0475, 0.025), (-0.0475, -0.025)):
            out.append((wx + wc * a - ws * b, wy + ws * a + wc * b))
    worst = math.inf
    for bx, by in out:
        px, py = x + c * bx - s * by, y + s * bx + c * by
        dx = abs(px - box_center[0]) - box_size[0] / 2
        dy = abs(py - box_center[1]) - box_size[1] / 2
        gap = math.hypot(max(dx, 0.0), max(dy, 0.0)) if max(dx, dy) > 0.0 else max(dx, dy)
        worst = min(worst, gap)
    return worst


@pytest.mark.slow
def test_the_youbot_turns_between_its_stands_and_home_clear_of_the_pool():
    """The heading turns on a profile of its own while the base travels (Mecanum); turning
    fast near a stand must not swing a corner of the base into the pool's walls or platform
    (its corners reach 0.34 m from its centre, its sides 0.18 m, its wheels 0.209 m)."""
    layout = cell_layout()
    cell = FakeCell(layout, PAPER)
    assert run(cell).result.status == 'completed'
    world = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
    boxes = [(o.name, o.position, o.size) for o in world.obstacles
             if o.name.startswith('pool_wall') or o.name == 'pool_platform']
    assert len(boxes) == 5
    path = cell.path[::3]
    turned = max(abs(math.remainder(b[2] - a[2], 2 * math.pi)) / (3 * DT)
                 for a, b in zip(path, path[1:]))
    assert 0.5 < turned <= Settings().base_max_turn + 1e-6
    worst = min((_footprint_clearance(pose, center, size), name, tuple(np.round(pose, 3)))
                for pose in path for name, center, size in boxes)
    assert worst[0] >= 0.025, worst


def test_the_youbot_takes_a_stands_first_material_on_the_way_and_drops_it_there():
    """The material rides on the base's plate, so the arm can take it while the base drives;
    it lets go only once the base stands at the stand (over the pool or the platform)."""
    layout = cell_layout()
    cell = FakeCell(layout, PAPER)
    assert run(cell).result.status == 'completed'
    events = sorted(cell.events, key=lambda e: e.time)
    drives = [e for e in events if e.kind == 'driving' and not e.detail.startswith('to home')]
    assert [e.detail.split(',')[0] for e in drives] == [f'to {st.name}' for st in layout.stands]

    def first(kind, after):
        return next(e for e in events if e.kind == kind and e.time >= after.time)
    for drive in drives:
        arrived, grasped = first('arrived', drive), first('unload_grasped', drive)
        delivered = first('delivered', drive)
        assert grasped.time < arrived.time <= delivered.time, (drive, grasped, arrived)
        assert grasped.material == delivered.material
        stand = layout.stand(arrived.detail).pose
        at_drop = cell.path[round(delivered.time / DT) - 1]
        assert np.hypot(*(at_drop[:2] - np.asarray(stand[:2]))) < 0.02
    # Every other unload starts with the base standing.
    standing = [e for e in kinds(cell, 'unload_grasped')
                if not any(e.material == first('unload_grasped', d).material for d in drives)]
    assert len(standing) == 5
    assert all(np.linalg.norm(cell.path[round(e.time / DT) - 1][:2]
                              - cell.path[round(e.time / DT) - 2][:2]) < 1e-9
               for e in standing)


def _watch_materials(cell: FakeCell) -> Dict[int, List[tuple]]:
    """Record each material's (time, x) while the belt carries it."""
    history: Dict[int, List[tuple]] = {}
    step = cell.step

    def watching_step():
        obs = step()
        for i, m in cell.materials.items():
            if m[3]:
                history.setdefault(i, []).append((cell.now, m[0]))
        return obs
    cell.step = watching_step
    return history


def _x_at(history, t):
    return min(history, key=lambda s: abs(s[0] - t))[1]


def _contact_time(event) -> float:
    return float(re.search(r'contact at ([0-9.]+) s', event.detail).group(1))


@pytest.mark.parametrize('belt_latency', [0.0, 0.15])
def test_the_belt_never_stops_and_the_cup_meets_each_material_where_it_is(belt_latency):
    # With belt_latency the belt starts 0.15 s after the decision and the port cannot tell:
    # the frames correct the model.
    layout = cell_layout()
    cell = FakeCell(layout, PAPER, belt_latency=belt_latency)
    history = _watch_materials(cell)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert not kinds(cell, 'grasp_missed')
    # Started once, stopped when loading was over (and again by the run's end, to be sure).
    assert cell.belt_calls[0] == layout.belt_speed and set(cell.belt_calls[1:]) == {0.0}
    assert [e.kind for e in cell.events if e.kind.startswith('belt')] == ['belt_started',
                                                                          'belt_stopped']
    tracking = kinds(cell, 'tracking')
    picked = [e.material for e in kinds(cell, 'picked')]
    assert [e.material for e in tracking] == picked and len(picked) == 8
    picks = [pts for arm, t, pts in cell.trajectories if arm == 'zu12'
             and any(abs(t - e.time) < 1e-9 for e in tracking)]
    assert len(picks) == 8
    dwell = Settings().timing.dwell
    for e, points in zip(tracking, picks):
        # The fake's joint vector is the tool position: from contact to the end of the dwell
        # the cup is on the material's top face, moving with it (the cup sealed there).
        t_contact = _contact_time(e)
        on = [(t, q) for t, q, *_ in points
              if t_contact - 1e-9 <= t <= t_contact + dwell + 1e-9]
        assert len(on) >= 3
        for t, q in on:
            if t <= history[e.material][-1][0]:
                x = _x_at(history[e.material], t)
                assert abs(q[0] - x) <= layout.belt_speed * DT + 1e-6
        # (The fake's cup seals within 2 mm of the top face: in the last 0.1 s of the descent.)
        assert cell.final_x[e.material] == pytest.approx(on[0][1][0], abs=0.02)
    # The oranges and the blue are taken on the move while the arm keeps up with them; the
    # purple rides to the end and is taken there.
    purple = [e for e in tracking if e.color == 'purple']
    assert len(purple) == 1 and 'held at the stop' in purple[0].detail
    on_the_move = [e for e in tracking if e.color != 'purple' and 'held' not in e.detail]
    assert len(on_the_move) >= 3
    stop_x = layout.belt_end_x - layout.material_size / 2
    assert cell.final_x[purple[0].material] == pytest.approx(stop_x, abs=1e-3)


def test_materials_faster_than_the_arm_wait_at_the_end_stop():
    # Materials close together reach the end while the arm is still busy: the stop holds them
    # in a queue and the arm takes them from there; nothing goes off the end. (The arm at half
    # its speed: materials outpace it whatever its schedule.)
    layout = cell_layout()
    cell = FakeCell(layout, PAPER, gap=0.06)
    history = _watch_materials(cell)
    p = run(cell, Settings(loader_scaling=0.5))
    assert p.result.status == 'completed' and p.result.missed == 0
    furthest = max(x for h in history.values() for _, x in h)
    assert furthest <= layout.belt_end_x - layout.material_size / 2 + 1e-9
    assert sum('held at the stop' in e.detail for e in kinds(cell, 'tracking')) >= 3


def test_a_missed_grasp_is_retried():
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={2: 1})
    p = run(cell)
    assert p.result.status == 'completed'
    missed = kinds(cell, 'grasp_missed')
    assert [(e.material, e.detail) for e in missed] == [(2, 'attempt 1')]
    assert [e.detail for e in kinds(cell, 'picked') if e.material == 2] == ['attempt 2']
    assert p.result.grasp_attempts == 16 and p.result.grasp_successes == 15
    # The pick's motion went on to the place through the lift point; nothing held after the
    # dwell, it was replaced by one from where it had the arm (moving) to rest at the lift
    # point, where the miss was judged.
    sent = [pts for arm, t, pts in cell.trajectories if arm == 'zu12' and t < missed[0].time]
    whole, cut = sent[-2], sent[-1]
    t1, q1, v1, _ = cut[0]
    same = [p for p in whole if p[0] == t1]
    assert same and np.allclose(same[0][1], q1) and np.allclose(same[0][2], v1) and np.any(v1)
    assert cut[-1][0] < whole[-1][0] - 0.5 and not np.any(cut[-1][2])
    assert cut[-1][0] <= missed[0].time
    assert min(np.max(np.abs(p[1] - cut[-1][1])) for p in whole) < 0.01     # on its way
    slots = [e.detail for e in kinds(cell, 'loaded')]
    assert len(set(slots)) == len(slots) == 7


def test_in_real_time_a_missed_grasp_stops_the_arm_from_its_running_motion():
    """Real time: the stop at the lift point is sent a plan latency ahead, while the pick's
    motion runs on. It repeats that motion's samples until the stop begins and is stamped at
    the decision, so that the controller joins it from where the running motion has the arm
    (a message starting a second later, from rest, was refused by the simulator: the joints
    would have had to jump to the running motion's sample; the arm then held still and the
    pick stalled, in CI)."""
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={2: 1})
    p = run(cell, Settings(plan_latency=1.0))
    assert p.result.status == 'completed'
    missed = kinds(cell, 'grasp_missed')
    assert [(e.material, e.detail) for e in missed] == [(2, 'attempt 1')]
    assert not kinds(cell, 'arm_stalled')
    (arm, sent_at, start, cut), = cell.continuations
    whole = [pts for a, t, pts in cell.trajectories if a == 'zu12' and t < sent_at][-1]
    assert start == sent_at
    ahead = [q for q in whole if sent_at < q[0] < sent_at + 1.0]
    assert ahead, 'the running motion had samples within the plan latency'
    for mine, theirs in zip(cut, ahead):         # the running motion's own samples first
        assert mine[0] == theirs[0] and np.array_equal(mine[1], theirs[1])
    assert not np.any(cut[-1][2])                               # to rest, at the lift point
    assert min(np.max(np.abs(q[1] - cut[-1][1])) for q in whole) < 0.01


def test_a_pick_that_can_no_longer_meet_its_material_is_called_off_at_once(monkeypatch):
    """Re-aiming finds no motion that meets the material, and the pick would meet it 50 mm off
    its centre: the arm stops where it is (at rest, from its running motion), the cup off, and
    the attempt is judged missed then, not at the lift point a second or more later; the
    material is picked on the next attempt."""
    from coordinator.pipeline.model import REAIM_LEAD_S
    from coordinator.pipeline.pick_planner import PickPlanner
    told = []
    reaim = PickPlanner.reaim

    def cannot(self, obs, pick, running):
        t1 = self.arm.clock.now + self.s.plan_latency
        if (pick.m.id == 3 and not told
                and pick.reaim_from <= t1 < pick.hover_at - REAIM_LEAD_S):
            told.append((obs.now, pick.contact))
            pick.reaimed = 0.05
            return 'not re-aimed (the arm cannot meet the material in time): the pick goes on'
        return reaim(self, obs, pick, running)
    monkeypatch.setattr(PickPlanner, 'reaim', cannot)
    cell = FakeCell(cell_layout(), PAPER)
    p = run(cell)
    assert p.result.status == 'completed'
    (when, contact), = told
    called = [e for e in kinds(cell, 'replanned') if e.material == 3]
    assert [e.detail for e in called] == [
        'not re-aimed (the arm cannot meet the material in time): called off']
    missed = [e for e in kinds(cell, 'grasp_missed') if e.material == 3]
    assert [e.detail for e in missed] == ['attempt 1']
    assert missed[0].time < contact          # judged before the cup would have come down
    arm, sent_at, start, stop = [c for c in cell.continuations if c[1] == when][0]
    assert arm == 'zu12' and not np.any(stop[-1][2]) and stop[-1][0] < contact
    assert [e.detail for e in kinds(cell, 'picked') if e.material == 3] == ['attempt 2']


@pytest.mark.parametrize('drift', [
    pytest.param(lambda t: 1.15, id='15 % fast'), pytest.param(lambda t: 0.85, id='15 % slow'),
    # (As the perturbed world drifts it: two incommensurate sines, up to 15 %, period 20 s.)
    pytest.param(lambda t: 1.0 + 0.15 * (0.7 * math.sin(2 * math.pi * t / 20.0 + 1.0)
                                         + 0.3 * math.sin(2 * math.pi * t / 20.0 * 2.618)),
                 id='wandering')])
def test_the_cup_meets_materials_on_a_belt_that_does_not_run_at_its_set_speed(drift):
    """The belt's speed is the one its tracks show, not its set point: predicted from the set
    point, a material met 2 s after the plan is 3 cm from the cup on a belt 15 % off (the fake
    cup seals within 1 cm), and missed."""
    cell = FakeCell(cell_layout(), PAPER, belt_drift=drift)
    p = run(cell)
    assert p.result.status == 'completed'
    assert not kinds(cell, 'grasp_missed')
    assert all(e.detail.startswith('re-aimed') for e in kinds(cell, 'replanned'))
    # What the cell sensed is in its events: the belt's speed, with its uncertainty.
    for e in kinds(cell, 'tracking'):
        sensed = re.search(r'belt ([0-9.]+) \+- ([0-9.]+) m/s \(vision, (\d+) tracks, '
                           r'([0-9.]+) s old\)', e.detail)
        assert sensed, e.detail
        # (The tracks of the WINDOW_S before its newest sighting: the belt's mean speed over
        # them; the belt ran all the while.)
        newest = e.time - float(sensed.group(4))
        ts = np.linspace(newest - WINDOW_S, newest, 61)
        true = cell.layout.belt_speed * float(np.mean([drift(t) for t in ts]))
        assert abs(float(sensed.group(1)) - true) < 0.001 + 3 * float(sensed.group(2)), (
            e.detail, true)


def test_a_material_missed_on_the_move_is_picked_at_rest_at_the_end_stop():
    """Its picks on the move missed (max_retries + 1 of them): it was given up, although it
    then rested at the end stop, where 435 of 445 picks of the perturbed sweep took theirs.
    It rides on there and is picked at rest."""
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={3: 2})
    p = run(cell, Settings(max_retries=1))
    assert p.result.status == 'completed' and not kinds(cell, 'grasp_failed')
    assert [e.detail for e in kinds(cell, 'grasp_missed') if e.material == 3] == [
        'attempt 1', 'attempt 2']
    deferred, = [e for e in kinds(cell, 'replanned') if e.material == 3]
    assert 'picked again at rest at the end stop' in deferred.detail
    picked, = [e for e in kinds(cell, 'picked') if e.material == 3]
    assert picked.detail == 'attempt 3'
    tracking = [e for e in kinds(cell, 'tracking') if e.material == 3]
    assert 'held at the stop' in tracking[-1].detail
    assert all('held at the stop' not in e.detail for e in tracking[:-1])
    # Met at the stop: the cup came down where it rests.
    stop = cell.layout.belt_end_x - cell.layout.material_size / 2
    assert cell.final_x[3] == pytest.approx(stop, abs=0.06)


def test_a_material_missed_at_the_end_stop_is_tried_again_there():
    """The purple rides to the end stop and is picked there; both attempts missed: it was
    given up, although as many again are given to one missed on the move."""
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={2: 2})
    p = run(cell, Settings(max_retries=1))
    assert p.result.status == 'completed' and not kinds(cell, 'grasp_failed')
    tracking = [e for e in kinds(cell, 'tracking') if e.material == 2]
    assert len(tracking) == 3 and all('held at the stop' in e.detail for e in tracking)
    assert [e.detail for e in kinds(cell, 'picked') if e.material == 2] == ['attempt 3']


def test_a_grasp_that_keeps_missing_is_reported_and_the_run_goes_on():
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={3: 5})
    p = run(cell, Settings(max_retries=1))
    r = p.result
    assert r.status == 'incomplete'
    failed = kinds(cell, 'grasp_failed')
    assert [e.material for e in failed] == [3]
    assert failed[0].detail == 'not held after 4 attempts (2 at rest at the end stop)'
    assert r.delivered == 7 and r.failed == 1
    # The belt went on after the failure and the youBot still delivered the rest.
    assert len(kinds(cell, 'delivered')) == 6


def test_materials_that_leave_the_belt_unpicked_are_counted_missed():
    layout = dataclasses.replace(cell_layout(), end_stop=False)   # a belt they fall off
    cell = FakeCell(layout, PAPER[:3])
    p = run(cell, Settings(pick_x=layout.belt_end_x + 1.0, idle_timeout=5.0))
    r = p.result
    assert r.status == 'incomplete' and r.missed == 3 and r.delivered == 0
    assert {e.material for e in kinds(cell, 'missed')} == {1, 2, 3}
    assert not kinds(cell, 'departing')           # nothing to carry: the youBot stays


def test_a_silent_vision_ends_the_loading_after_the_idle_timeout():
    cell = FakeCell(cell_layout(), PAPER, blind=True)
    p = run(cell, Settings(idle_timeout=5.0))
    assert p.result.status == 'incomplete' and p.result.identified == 0
    over = kinds(cell, 'loading_over')
    assert over and 'nothing new for 5 s' in over[0].detail
    assert over[0].time == pytest.approx(5.0, abs=2 * DT)


@pytest.mark.parametrize('where', ['solve', 'grip'])
def test_a_node_that_stops_answering_ends_the_run_safely(where):
    cell = FakeCell(cell_layout(), PAPER, timeout_on=where)
    p = run(cell)
    assert p.result.status == 'node_timeout'
    assert 'did not answer' in p.result.message
    assert cell.belt_calls[-1] == 0.0 and cell.drive_calls[-1] == (0.0, 0.0, 0.0)


def test_a_stalled_arm_is_detected_by_the_state_deadline():
    cell = FakeCell(cell_layout(), PAPER[:1], stall=True)
    p = run(cell, Settings(idle_timeout=5.0))
    assert p.result.status == 'incomplete'
    failed = kinds(cell, 'grasp_failed')
    assert failed and 'did not reach the material' in failed[0].detail
    assert not kinds(cell, 'picked')
    # A state ends at its motion's planned end plus the settle margin; the pick is tried once
    # more (the material rides on, untouched) before it fails. The pick's motion went on to
    # the place; nothing held after the dwell, it was cut short to end at the lift point.
    # (As many again once it rests at the end stop.)
    stalled = kinds(cell, 'arm_stalled')
    assert len(stalled) == 2 * (Settings().max_retries + 1)
    assert failed[0].detail.endswith('(2 at rest at the end stop)')
    pick = [e.time for e in cell.events if e.kind == 'state' and e.detail == 'pick'][0]
    # The pick's motion goes on to the place; an arm that does not follow it is judged at
    # the time it was to be at rest at the lift point.
    (_, sent, whole), = [t for t in cell.trajectories if t[0] == 'zu12'][:1]
    timing = Settings().timing
    lift_end = _contact_time(kinds(cell, 'tracking')[0]) + timing.dwell + timing.lift
    assert sent == pick and lift_end < whole[-1][0] - 0.5
    margin = Settings().settle_margin
    assert lift_end + margin <= stalled[0].time + DT < whole[-1][0] + margin - 0.5


def test_a_material_dropped_on_the_way_is_reported():
    cell = FakeCell(cell_layout(), PAPER, drop_on_transfer=3)
    p = run(cell)
    failed = kinds(cell, 'grasp_failed')
    assert [e.material for e in failed] == [3] and 'dropped' in failed[0].detail
    assert p.result.delivered == 7


def test_an_unreachable_pick_is_reported_not_attempted():
    far = lambda arm, p: arm == 'zu12' and p[2] > 0.5 and p[1] > 0.7   # noqa: E731
    cell = FakeCell(cell_layout(), PAPER[:2], unreachable=far)
    p = run(cell, Settings(idle_timeout=5.0))
    assert p.result.picked == 0 and p.result.failed == 2
    assert kinds(cell, 'ik_failed') and p.result.grasp_attempts == 0


def test_a_pool_drop_out_of_reach_is_swapped_for_another():
    # The arm cannot reach the first drop of the right stand (seed 0 on a loaded machine:
    # from the far slot, as the base stood, no tilt reached its drop): the material goes to
    # the stand's next drop (it has a spare) instead of failing.
    layout = cell_layout()
    from cell_layout.layout import world_to_base
    blocked = []
    stand = layout.stand('pool_right')
    b = world_to_base(stand.pose, stand.drops[0])
    b[2] -= layout.youbot_base_z
    blocked.append(b)

    def unreachable(arm, p):
        return arm == 'youbot' and any(np.linalg.norm(np.asarray(p) - b) < 0.02
                                       for b in blocked)
    assert blocked
    cell = FakeCell(layout, PAPER, unreachable=unreachable)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert p.result.delivered == 8
    drops = [e.detail for e in kinds(cell, 'delivered') if e.detail.startswith('pool_floor')]
    spots = [re.sub(r' \(let go [^)]*\)', '', d) for d in drops]
    assert 'pool_floor drop 0 from pool_right' not in spots and len(set(spots)) == 6


def test_a_base_that_does_not_move_ends_with_a_result():
    cell = FakeCell(cell_layout(), PAPER[:2], drive_works=False)
    p = run(cell, Settings(run_timeout=200.0, drive_margin=5.0))
    assert p.finished
    assert kinds(cell, 'drive_stalled')
    assert p.result.status in ('incomplete', 'timeout')


def test_the_run_timeout_ends_a_run_in_progress():
    cell = FakeCell(cell_layout(), PAPER)
    p = run(cell, Settings(run_timeout=20.0))
    assert p.result.status == 'timeout' and p.result.completion_time <= 20.0 + 2 * DT


def test_the_same_inputs_give_the_same_events():
    a, b = FakeCell(cell_layout(), PAPER), FakeCell(cell_layout(), PAPER)
    run(a), run(b)
    assert [(e.time, e.kind, e.material, e.detail) for e in a.events] == \
        [(e.time, e.kind, e.material, e.detail) for e in b.events]


def test_youbot_tool_orientation_leans_outwards_in_the_arm_plane():
    from controllers.transforms import quaternion_to_matrix
    r = quaternion_to_matrix(youbot_tool_quaternion((-0.1, 0.11, 0.1), math.radians(30)))
    z = r[:, 2]
    assert z[2] == pytest.approx(-math.cos(math.radians(30)))
    # Leaning away from the arm base (at x = 0.167), towards the target's side.
    assert z[0] < 0 and z[1] > 0
    assert np.allclose(r.T @ r, np.eye(3))


def test_the_layout_of_the_cell_world():
    layout = cell_layout()
    assert layout.total == 8 and layout.plate_bound() == 7
    assert layout.destination('blue') == 'pool_platform'
    assert layout.destination('orange') == 'pool_floor'
    # The youBot's front (0.285 m ahead) stays west of the pool's west wall at both stands.
    assert all(st.pose[0] + 0.18 < 2.08 for st in layout.stands)   # side-on to the wall


def test_a_world_without_the_cell_is_refused():
    world = load_world(resolve_resource('package://world_description/worlds/youbot.yaml'))
    with pytest.raises(LayoutError, match='conveyor'):
        layout_from_world(world)


def test_real_time_plans_leave_room_for_the_plan_latency():
    fast, slow = FakeCell(cell_layout(), PAPER[:1]), FakeCell(cell_layout(), PAPER[:1])
    run(fast, Settings(idle_timeout=3.0))
    run(slow, Settings(idle_timeout=3.0, plan_latency=0.5))
    first = [pts[0][0] - t for arm, t, pts in fast.trajectories]
    later = [pts[0][0] - t for arm, t, pts in slow.trajectories]
    assert len(first) == len(later)
    # Every motion's first point comes 0.5 s later relative to its decision; a pick's, which
    # meets the material where the belt has carried it by then, at least 0.5 s after it.
    picks = [e.time for e in kinds(slow, 'tracking')]
    assert picks
    for (_arm, t, _), a, b in zip(slow.trajectories, first, later):
        if t in picks:
            assert b >= 0.5
        else:
            assert b - a == pytest.approx(0.5, abs=1e-6)



def test_a_motion_the_port_starts_later_is_judged_by_its_real_end():
    # Real time: planning took 3 s longer than its allowance, so the port started every motion
    # 3 s late; judged by the planned end plus the 2 s settle margin, each would have stalled.
    cell = FakeCell(cell_layout(), PAPER, send_lag=3.0)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert not kinds(cell, 'arm_stalled') and not kinds(cell, 'grasp_missed')
    assert p.result.grasp_attempts == p.result.grasp_successes == 15


def test_a_pick_planned_slower_than_its_allowance_is_planned_again_and_made():
    # Real time: each IK call costs 0.06 s of simulated time, so a tracking pick's plan (about
    # thirty calls) takes longer than the 1 s allowed for it, and the port would start it late
    # (the CI machine's first pick: 0.64, 0.81, 1.44 s late, then missed). Each new plan
    # allows for the longest one has taken, after the time already spent: none is sent late.
    cell = FakeCell(cell_layout(), PAPER, solve_cost=0.06)
    p = run(cell, Settings(plan_latency=1.0))
    assert p.result.status == 'completed', p.result
    # Replanned only when a plan took longer than any before (the allowance grows to it), and
    # each time made at once by the next plan.
    replans = kinds(cell, 'replanned')
    assert replans and len(replans) <= 3, replans
    made = {(e.time, e.material) for e in kinds(cell, 'tracking')}
    assert all((e.time, e.material) in made for e in replans), replans
    assert p.result.grasp_attempts == p.result.grasp_successes == 15
    assert not kinds(cell, 'arm_stalled') and not kinds(cell, 'grasp_missed')


def test_an_unload_is_planned_once_the_arm_is_at_its_ready_pose():
    # The arm rises over the first material of a stand while the base drives there. Motions
    # started 5 s late: the ready motion outlasts the short drive between the pool's stands.
    # Planned from the moving arm, the unload's first point would be where the arm was, not
    # where it is (CI: "arm_joint_1 would move 0.73 in 0.048 s", refused).
    cell = FakeCell(cell_layout(), PAPER, send_lag=5.0)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert not cell.replaced, cell.replaced


@pytest.mark.parametrize('base_loop', [True, False])
def test_a_decision_held_up_by_planning_leaves_the_base_on_its_path(base_loop):
    # Real time under load: IK calls for the Zu 12 hold up decisions for half a second at a
    # time while the youBot drives. The port's base controller runs the path on, and the base
    # stays within centimetres of it; left on the last decision's command, it runs off its
    # path (CI: 0.5 m past its stand, and the plate's load thrown off).
    cell = FakeCell(cell_layout(), PAPER, solve_cost=0.01, base_loop=base_loop)
    p = run(cell, Settings(plan_latency=1.0), lag=lambda now: 15)
    worst = max(cell.drive_errors)
    if base_loop:
        assert p.result.status == 'completed', p.result
        assert worst < 0.01, worst
    else:
        assert worst > 0.05, worst      # (what the test would see without the base loop)


def test_a_pick_the_simulator_refused_is_made_again():
    # The arm never moved: judged at the deadline, the material rides on, untouched, and the
    # next attempt takes it.
    cell = FakeCell(cell_layout(), PAPER, refuse_picks=1)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert [(e.material, e.kind) for e in kinds(cell, 'arm_stalled')] == [(1, 'arm_stalled')]
    assert p.result.grasp_attempts == p.result.grasp_successes + 1 == 16


def test_a_material_left_on_the_belt_still_queues_at_the_stop():
    # Both attempts on the move at the first material refused: it rides on to the end stop,
    # and is picked there at rest. The belt model keeps it there meanwhile, so what queues
    # behind it (the purple last of all) is met where it really is.
    cell = FakeCell(cell_layout(), PAPER, refuse_picks=2)
    p = run(cell)
    assert p.result.status == 'completed' and p.result.delivered == 8
    first = [e for e in cell.events if e.material == 1 and e.kind in ('tracking', 'picked')]
    assert 'held at the stop' in first[-2].detail and first[-1].detail == 'attempt 3'
    assert cell.final_x[1] == pytest.approx(cell.layout.belt_end_x - 0.025)
    assert not kinds(cell, 'grasp_missed'), kinds(cell, 'grasp_missed')


def test_a_coordinator_that_lags_the_simulator_still_delivers_everything():
    # Real time under load: the coordinator misses up to 0.5 s of observations at a time. Every
    # step of a pick or an unload is gated by feedback (the arm at its goal, the tool's state),
    # never by the plan's times, so a late look changes when, not whether.
    import random
    rng = random.Random(3)
    cell = FakeCell(cell_layout(), PAPER)
    p = run(cell, lag=lambda now: rng.choice([0, 0, 1, 3, 15]))
    assert p.result.status == 'completed', p.result
    assert p.result.grasp_attempts == p.result.grasp_successes == 15
    assert not kinds(cell, 'arm_stalled')


def test_the_youbot_closes_its_gripper_only_at_the_material():
    # Its 20 mm reach would take a neighbour on the way down: it closes once the arm is at the
    # contact pose, and judges the grasp on a grip state that shows the gripper closed.
    cell = FakeCell(cell_layout(), PAPER[:3])
    closes, grip = [], cell.grip

    def recording_grip(arm, on):
        if arm == 'youbot' and on:
            closes.append((cell.now, cell.now >= cell.goal['youbot'][0]))
        return grip(arm, on)
    cell.grip = recording_grip
    p = run(cell, Settings(idle_timeout=3.0))
    assert p.result.delivered == 3
    assert len(closes) == 2 and all(at_rest for _, at_rest in closes)


def test_an_arm_still_moving_near_its_goal_has_not_arrived():
    # The simulator took each motion in 0.4 s late: at the end the plan gives, the arm is within
    # the arrival tolerance of its goal but still moving. Nothing grips or lets go until it is
    # at rest there (a blue released while the arm still moved slid off the platform).
    cell = FakeCell(cell_layout(), PAPER, taken_late=0.4)
    p = run(cell)
    assert p.result.status == 'completed', p.result
    assert p.result.grasp_attempts == p.result.grasp_successes == 15
    assert cell.grips_while_moving == []


def test_a_material_the_camera_sees_in_the_cup_beside_the_belt_is_not_a_new_one():
    # The ground target is beside the belt under the camera: carried there, the purple shows up
    # in the frames as a new track.
    cell = FakeCell(cell_layout(), PAPER, held_in_view=True)
    p = run(cell)
    assert any(i > 100 for i in cell.hits), 'the fake camera never saw a held material'
    assert p.result.status == 'completed' and p.result.identified == len(PAPER)


def test_the_zu12_crosses_the_belts_edge_low_and_clear_instead_of_rising_to_carry_height():
    """Between the belt and the plate the cup goes over the belt's near edge (the fake cell's
    joints are the cup's position) with what it holds 5 cm over what rides on the belt, and
    its empty cup 5 cm over that too, and does not rise higher beside the belt (to the carry
    height over the place, say)."""
    layout = cell_layout()
    cell = FakeCell(layout, PAPER)
    track: List[tuple] = []
    step = cell.step

    def watching_step():
        obs = step()
        track.append((cell.now, cell.q['zu12'][:3].copy(), cell.holding['zu12']))
        return obs
    cell.step = watching_step
    assert run(cell).result.status == 'completed'
    size, top = layout.material_size, layout.belt_top
    transfer = top + 2 * size + Settings().timing.lift_height
    edge = layout.belt_y - layout.belt_width / 2
    # (Onto the plate; the purple, last, goes onto the ground target, 5 cm over the belt.)
    purple = min(e.time for e in kinds(cell, 'picked') if e.color == 'purple')
    crossing = [p for t, p, held in track
                if held and t < purple and edge - size / 2 <= p[1] <= edge + size / 2]
    assert crossing and min(p[2] - size for p in crossing) >= top + size + 0.04
    # Beside the belt (the plate's side): carrying, and from a place straight on to a pick
    # (when nothing is there to pick yet, the cup waits up at the carry height).
    beside = lambda p: p[1] < edge - size                      # noqa: E731
    assert max(p[2] for _, p, held in track if held and beside(p)) < top + 2 * size + 0.06
    picks = {e.time for e in kinds(cell, 'tracking')}
    onward = [e.time for e in kinds(cell, 'loaded') if e.time in picks]
    assert len(onward) >= 3
    back = [p[2] for t, p, held in track if not held and beside(p)
            and any(t0 < t < t0 + 2.0 for t0 in onward)]
    assert back and max(back) < top + size + 0.06, (max(back), transfer)


class _YoubotIK:
    """Ports with the youBot's real IK (the unload paths' geometry), and nothing else."""

    def __init__(self) -> None:
        from controllers.youbot_kinematics import YoubotKinematics
        self.kin = YoubotKinematics()

    def solve(self, arm, position, orientation, frame, seed):
        from controllers.transforms import pose_matrix
        solution = self.kin.ik(pose_matrix(position, orientation), seed=seed)
        return (solution.positions, '') if solution.success else (None, solution.reason)

    def event(self, event):
        pass


class Zu12IK:
    """Ports with the Zu 12's real IK (its swings' and lifts' geometry), and nothing else."""

    def __init__(self) -> None:
        from controllers.zu12_kinematics import Zu12Kinematics
        self.kin = Zu12Kinematics('suction_tcp')

    def solve(self, arm, position, orientation, frame, seed):
        from controllers.transforms import pose_matrix
        solution = self.kin.ik(pose_matrix(position, orientation), seed=seed)
        return (solution.positions, '') if solution.success else (None, solution.reason)

    def event(self, event):
        pass


def _hermite(points, steps=8):
    """The controller's path between samples (cubic in position and velocity)."""
    for (t0, q0, v0, _), (t1, q1, v1, _) in zip(points, points[1:]):
        h = t1 - t0
        for x in np.linspace(0.0, 1.0, steps, endpoint=False):
            yield ((2 * x**3 - 3 * x**2 + 1) * q0 + (x**3 - 2 * x**2 + x) * h * v0
                   + (-2 * x**3 + 3 * x**2) * q1 + (x**3 - x**2) * h * v1)


@pytest.mark.parametrize('color', ['orange', 'blue'])
def test_the_youbot_lifts_a_material_straight_off_its_plate_until_clear_of_its_neighbours(
        color):
    """Plate slots are 1 cm apart. From every slot, with every other slot full, the material
    rises straight up, untilted, until it is over its neighbours' tops (a joint motion from the
    grip to the top of the lift swung it 2 cm sideways and tilted it 8 degrees), and on its way
    to the drop it passes over the other materials, never into them (a swing from the lift's
    top down to a pool drop lower than the plate knocked one over: campaign trial 31)."""
    from cell_layout.layout import PLATE_SLOTS_IN_BASE_M, PLATE_TOP_IN_BASE_M
    from coordinator.pipeline import YOUBOT_GRASP_STANDOFF_M, Material, clear_of_the_plate
    ports = _YoubotIK()
    layout = cell_layout()
    run = Pipeline(layout, ports, Settings())
    transport, size = run.transport, layout.material_size
    slots = PLATE_SLOTS_IN_BASE_M
    for slot in range(len(slots)):
        run.materials.clear()
        run.materials.update({k + 10: Material(k + 10, 'orange', np.zeros(3), 0.0, 3,
                                               status='on_plate', slot=k)
                              for k in range(len(slots)) if k != slot})
        m = Material(1, color, np.zeros(3), 0.0, 3, status='on_plate', slot=slot)
        run.materials[1] = m
        path = transport.planner.unload_path(m, layout.stand_for(color, slot).pose, YOUBOT_CARRY_Q)
        assert path is not None
        transport._carry = path
        obs = observation(0.0, np.zeros(6), path.contact.copy(), (0.0, 0.0, 0.0))
        if color == 'blue':
            motion = transport._lift(obs, m, [Waypoint(path.over, stop=False),
                                              Waypoint(path.drop)])
        else:
            motion = transport._lift(obs, m, [Waypoint(path.drop)],
                                     [Waypoint(path.over, stop=False), Waypoint(path.drop)])
        # Held at the lift's top (the base still drives): straight up, clear of the others.
        assert clear_of_the_plate(transport._lift(obs, m), [
            (*slots[k], size) for k in range(len(slots)) if k != slot], size)
        limits = run.youbot.limits
        assert all(np.all(np.abs(v) <= limits.velocity) for _, _, v, _ in motion)
        grip = ports.kin.fk(path.contact)
        rose = False
        for q in _hermite(motion):
            tool = ports.kin.fk(q)
            bottom = tool[2, 3] - YOUBOT_GRASP_STANDOFF_M - size
            over = [k for k in range(len(slots)) if k != slot
                    and abs(tool[0, 3] - slots[k][0]) < size + 0.004
                    and abs(tool[1, 3] - slots[k][1]) < size + 0.004]
            assert not over or bottom > PLATE_TOP_IN_BASE_M + size + 0.005, (slot, over)
            if tool[2, 3] - grip[2, 3] > size:
                rose = True
            if rose:
                continue
            assert np.linalg.norm(tool[:2, 3] - grip[:2, 3]) < 0.001, slot
            tilt = np.arccos(np.clip((np.trace(grip[:3, :3].T @ tool[:3, :3]) - 1) / 2, -1, 1))
            assert np.degrees(tilt) < 0.5, slot
        assert rose
        assert np.allclose(motion[-1][1], path.drop)


@pytest.mark.parametrize('held, other, clear', [
    (0.04, 0.04, True),       # 2.5 cm over a 40 mm neighbour's top
    (0.04, 0.05, True),       # 1.5 cm over a 50 mm one
    (0.04, 0.06, False),      # 0.5 cm over a 60 mm one: not clear
])
def test_a_material_held_over_the_plate_clears_each_neighbour_by_its_own_height(
        held, other, clear):
    """The lift's check judges each material on the plate by its own edge: a 40 mm material
    held 2.5 cm over the top of a 40 mm neighbour clears it, but not a 60 mm one."""
    from cell_layout.layout import PLATE_SLOTS_IN_BASE_M, PLATE_TOP_IN_BASE_M
    from cell_layout.reach import youbot_tool_quaternion
    from cell_layout.unload_geometry import PLATE_CLEARANCE_M
    from coordinator.pipeline import YOUBOT_GRASP_STANDOFF_M, clear_of_the_plate
    ports = _YoubotIK()
    sx, sy = PLATE_SLOTS_IN_BASE_M[2]
    bottom = PLATE_TOP_IN_BASE_M + 0.04 + 0.025           # the held material's bottom
    tool = np.array([sx, sy, bottom + held + YOUBOT_GRASP_STANDOFF_M])
    q = next(q for q, _ in (ports.solve('youbot', tool, youbot_tool_quaternion(
        tool, math.radians(tilt)), 'base_link', np.zeros(5)) for tilt in range(0, 90, 10))
        if q is not None)
    still = [(0.0, q, np.zeros(5), np.zeros(5)), (0.1, q, np.zeros(5), np.zeros(5))]
    assert clear_of_the_plate(still, [(sx, sy, other)], held) is clear
    assert (bottom >= PLATE_TOP_IN_BASE_M + other + PLATE_CLEARANCE_M - 1e-9) is clear
    # Beside it (a slot on), nothing is under what it holds.
    assert clear_of_the_plate(still, [(sx - 0.064, sy, 0.06)], held)


def test_a_material_that_stands_close_beside_a_neighbour_lifts_straight_up_past_it():
    """A 60 mm cube (a perturbed one, 10 mm taller than loaded) stands 60 mm centre to centre
    from a 55 mm neighbour: nearer than their half edges and the 5 mm margin, so it was judged
    over its neighbour from its start, and no motion off the plate was found (4 materials left
    on the plate in a trial of the screening). Lifted straight up it stays beside it; moved
    towards it before it is clear of its top, it is over it."""
    from cell_layout.layout import PLATE_SLOTS_IN_BASE_M, PLATE_TOP_IN_BASE_M
    from cell_layout.reach import youbot_tool_quaternion
    from coordinator.pipeline import YOUBOT_GRASP_STANDOFF_M, clear_of_the_plate
    ports = _YoubotIK()
    sx, sy = PLATE_SLOTS_IN_BASE_M[2]
    held, other = 0.06, 0.055

    def at(dx, rise):
        tool = np.array([sx + dx, sy, PLATE_TOP_IN_BASE_M + held + YOUBOT_GRASP_STANDOFF_M
                         + rise])
        return next(q for q, _ in (ports.solve('youbot', tool, youbot_tool_quaternion(
            tool, math.radians(tilt)), 'base_link', np.zeros(5)) for tilt in range(0, 90, 10))
            if q is not None)

    def motion(*qs):
        return [(0.1 * k, q, np.zeros(5), np.zeros(5)) for k, q in enumerate(qs)]
    neighbour = [(sx + 0.060, sy, other)]
    up = motion(at(0.0, 0.0), at(0.0, 0.03), at(0.0, 0.07))
    assert clear_of_the_plate(up, neighbour, held, off_its_slot=True)
    assert not clear_of_the_plate(up, neighbour, held)       # (not off its slot: the margin)
    towards = motion(at(0.0, 0.0), at(0.004, 0.02), at(0.004, 0.07))
    assert not clear_of_the_plate(towards, neighbour, held, off_its_slot=True)
    # (Farther apart than the margin, the margin holds as before.)
    assert not clear_of_the_plate(motion(at(0.0, 0.0), at(0.004, 0.02)),
                                  [(sx + 0.066, sy, other)], held, off_its_slot=True)


def test_odometry_is_turned_into_the_cells_frame_from_the_bases_start_pose():
    """The youBot's odom frame is its start pose in the cell (REP-105): a pose in it, and its
    twist in the base's own frame, become a pose and a velocity along the cell's axes (what
    the coordinator's path follower steers by)."""
    import math

    from controllers.cell_odometry import odometry_in_cell
    home = (1.0, -0.5, math.pi / 2)
    pose, velocity = odometry_in_cell(home, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert pose == pytest.approx(home)
    # 1 m ahead in odom is 1 m along the cell's y (the start pose faces +y); the base, turned
    # a further quarter turn, drives along its own x: along the cell's -x.
    pose, velocity = odometry_in_cell(home, 1.0, 0.0, math.pi / 2, 0.3, 0.0, 0.2)
    assert pose == pytest.approx((1.0, 0.5, math.pi))
    assert velocity == pytest.approx((-0.3, 0.0, 0.2), abs=1e-12)
    # Sideways in its own frame (Mecanum): along the cell's -y there.
    _, velocity = odometry_in_cell(home, 1.0, 0.0, math.pi / 2, 0.0, 0.4, 0.0)
    assert velocity == pytest.approx((0.0, -0.4, 0.0), abs=1e-12)


@pytest.mark.parametrize('encoder', [0.0, 1e-4])
def test_where_the_conveyor_has_an_encoder_the_cell_carries_each_material_by_its_counts(
        encoder):
    """A belt that wanders 15 % about its set point (as the perturbed world's): from the
    tracks' speed alone, where the cell believes a material is drifts from where it is (11 mm
    before its pick here). Where the conveyor's drive has an encoder, the cell carries each
    material by the counts since it saw it: within three counts (0.3 mm) of where it is at
    every step; and the speed it plans with is the drive's and the tracks' together."""
    from coordinator.pipeline.model import MaterialStatus

    class Watched(FakeCell):
        def step(self):
            if self.pipeline is not None:
                for m in self.pipeline.materials.values():
                    if (m.status == MaterialStatus.SEEN and not m.picked
                            and self.materials[m.id][3]):
                        errors.append(abs(m.position[0] - self.materials[m.id][0]))
            return super().step()

    def drift(t):
        return 1.0 + 0.15 * (0.7 * math.sin(2 * math.pi * t / 20.0 + 1.0)
                             + 0.3 * math.sin(2 * math.pi * t / 20.0 * 2.618))
    errors = []
    cell = Watched(dataclasses.replace(cell_layout(), belt_encoder=encoder), PAPER,
                   belt_drift=drift, encoder=encoder)
    p = run(cell)
    assert p.result.status == 'completed' and len(errors) > 500
    sources = {re.search(r'\((vision|encoder|set point)', e.detail).group(1)
               for e in kinds(cell, 'tracking')}
    if encoder:
        # (Read at 10 Hz: between two readings the belt is reckoned at the sensed speed, made
        # good at the next one.)
        assert max(errors) <= 3 * encoder and sources == {'encoder'}
    else:
        assert max(errors) > 0.005 and sources == {'vision'}
