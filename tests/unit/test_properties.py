"""Property-based tests (hypothesis) of the ROS-free validators that stand between a user's
input and the physics: trajectories, twists, world files, camera info, IK requests and what a
web page sends the control panel.

Each draws inputs from everything a careless or hostile sender could put in the message,
NaN, infinities, 1e308, negative and zero times, wrong sizes, and checks that the validator
answers (never raises) and that what it lets through is safe: finite, within the limits, and
(for a planned IK motion) taken by the simulator's own trajectory validation. Runs are
derandomised, so a failure is reproduced by running the test again.
"""
import copy
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from controllers.arm_model import MAX_MOTION_S, plan_ik
from controllers.cmd_guard import CommandGuard, non_finite_fields, rate_limited
from controllers.joint_trajectory import (
    INTERPOLATION_MARGIN,
    JointLimits,
    TrajectoryFollower,
    TrajectoryPoint,
    TrajectoryRequest,
)
from controllers.youbot_kinematics import YoubotKinematics
from perception.projection import CameraModel, intrinsics_problem
from teleop.panel_core import _OPS, MAX_MESSAGE_BYTES, PanelInputError, parse_command
from teleop.teleop_core import MOTIONS
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world, parse_world

SETTINGS = settings(derandomize=True, database=None, deadline=None, max_examples=300,
                    suppress_health_check=[HealthCheck.too_slow])

# Every float a message can carry, the awkward ones often.
ANY_FLOAT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e308, -1e308, math.nan, math.inf, -math.inf]),
    st.floats(-10.0, 10.0))

NAMES = ('j1', 'j2', 'j3')
LIMITS = JointLimits(lower=np.array([-2.0, -1.0, -3.0]), upper=np.array([2.0, 1.5, 3.0]),
                     velocity=np.array([1.0, 1.0, 2.0]), effort=np.ones(3),
                     acceleration=np.array([6.0, 6.0, 12.0]))


@st.composite
def trajectories(draw):
    """Half of them well formed (to check what is followed), half anything at all."""
    clean = draw(st.booleans())
    if clean:
        names = draw(st.permutations(NAMES))
    else:
        names = draw(st.one_of(st.permutations(NAMES), st.lists(
            st.sampled_from(NAMES + ('elbow',)), min_size=0, max_size=4).map(tuple)))
    count = draw(st.integers(1 if clean else 0, 6))
    size = len(names) if clean or draw(st.booleans()) or not names else draw(st.integers(0, 4))
    sane = st.floats(-0.9, 0.9)
    value = sane if clean else st.one_of(sane, sane, sane, ANY_FLOAT)
    values = st.lists(value, min_size=size, max_size=size)
    with_vel, with_acc = draw(st.booleans()), draw(st.booleans())
    time = 0.0
    points = []
    for _ in range(count):
        step = draw(st.floats(2.0, 4.0))
        time = time + step if clean else draw(st.one_of(st.just(time + step), ANY_FLOAT))
        points.append(TrajectoryPoint(
            time, tuple(draw(values)),
            tuple(draw(values)) if with_vel else (),
            tuple(draw(values)) if with_vel and with_acc else ()))
    start = draw(st.one_of(st.none(), st.floats(9.0, 12.0) if clean else ANY_FLOAT))
    if start is not None and not math.isfinite(start):
        start = None            # (a stamp is whole seconds and nanoseconds: always finite)
    return TrajectoryRequest(names, tuple(points), start)


@SETTINGS
@given(request=trajectories(), current=st.lists(st.floats(-0.9, 0.9), min_size=3, max_size=3))
def test_a_trajectory_is_refused_with_a_reason_or_followed_finite_and_within_limits(request,
                                                                                   current):
    follower = TrajectoryFollower(NAMES, LIMITS, current)
    result = follower.set_trajectory(request, now=10.0)
    event('accepted' if result.accepted else 'refused')
    if not result.accepted:
        assert result.reason
        assert not follower.active                   # holds where it was
        assert follower.sample(11.0).positions == pytest.approx(current)
        return
    for point in request.points:
        if point.accelerations:
            assert np.all(np.abs(point.accelerations) <= LIMITS.acceleration[
                [NAMES.index(n) for n in request.joint_names]] * (1 + 1e-9))
    margin = INTERPOLATION_MARGIN * (LIMITS.upper - LIMITS.lower)
    end = follower.end_time if follower.active else 10.0
    for t in np.linspace(10.0, end + 0.5, 60):
        state = follower.sample(float(t))
        assert np.all(np.isfinite(state.positions)) and np.all(np.isfinite(state.velocities))
        assert np.all(state.positions >= LIMITS.lower - margin - 1e-9)
        assert np.all(state.positions <= LIMITS.upper + margin + 1e-9)


@SETTINGS
@given(command=st.lists(ANY_FLOAT, min_size=3, max_size=3), now=st.floats(0.0, 1e6),
       limits=st.lists(st.floats(1e-3, 10.0), min_size=3, max_size=3))
def test_a_twist_is_refused_and_stops_or_is_clamped_within_the_limits(command, now, limits):
    guard = CommandGuard(limits, 0.5)
    guard.submit((0.1, 0.1, 0.1), now)
    result = guard.submit(command, now)
    if non_finite_fields(command + [0.0, 0.0, 0.0], ('x', 'y', 'z', 'a', 'b', 'c')):
        assert not result.accepted and result.reason
        assert guard.active_command(now) == (0.0, 0.0, 0.0)          # stopped
    else:
        assert result.accepted
        applied = guard.active_command(now)
        assert all(math.isfinite(v) and abs(v) <= lim for v, lim in zip(applied, limits))
    assert guard.active_command(now + 0.6) == (0.0, 0.0, 0.0)       # silence stops it


@SETTINGS
@given(current=st.lists(st.floats(-10, 10), min_size=3, max_size=3),
       target=st.lists(st.floats(-10, 10), min_size=3, max_size=3),
       steps=st.lists(st.floats(1e-6, 1.0), min_size=3, max_size=3))
def test_the_acceleration_limit_moves_each_component_by_at_most_its_step(current, target, steps):
    out = rate_limited(current, target, steps)
    for c, t, o, m in zip(current, target, out, steps):
        assert abs(o - c) <= m * (1 + 1e-12) + 1e-12
        assert o == t or abs(o - c) == pytest.approx(m)


CELL = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
WORLD_TEXT = __import__('yaml').safe_load(
    open(resolve_resource('package://world_description/worlds/pipeline_cell.yaml')))


def json_values(leaves):
    """Any JSON-like value (lists and mappings, a few levels deep) of ``leaves``."""
    return st.recursive(leaves, lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
        max_leaves=12)


JSONISH = json_values(st.one_of(st.none(), st.booleans(), ANY_FLOAT, st.integers(-10**6, 10**6),
                                st.text(max_size=12)))


def _paths(data, prefix=()):
    yield prefix
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(data, list):
        for i, value in enumerate(data):
            yield from _paths(value, prefix + (i,))


PATHS = [p for p in _paths(WORLD_TEXT) if p]


def _like(original):
    """Values of the original's kind (a number for a number, ...), and anything at all."""
    if isinstance(original, bool):
        return st.one_of(st.booleans(), JSONISH)
    if isinstance(original, (int, float)):
        return st.one_of(ANY_FLOAT, st.floats(-1e3, 1e3), st.integers(-10, 10), JSONISH)
    if isinstance(original, str):
        return st.one_of(st.text(max_size=20), st.just(original + 'x'), JSONISH)
    return JSONISH


def _at(data, where):
    for key in where:
        data = data[key]
    return data


@SETTINGS
@given(where_value=st.sampled_from(PATHS).flatmap(
    lambda where: st.tuples(st.just(where), _like(_at(WORLD_TEXT, where)))))
def test_a_world_file_with_any_field_changed_loads_or_fails_with_a_world_config_error(
        where_value):
    where, value = where_value
    data = copy.deepcopy(WORLD_TEXT)
    node = data
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = value
    try:
        config = parse_world(data, 'fuzzed.yaml')
    except WorldConfigError as exc:
        assert str(exc).startswith('fuzzed.yaml')            # names the file (and the field)
        event('refused')
        return
    event('loaded')
    assert isinstance(config.gravity, float) and math.isfinite(config.gravity)


@st.composite
def camera_infos(draw):
    """A size and K: half pinhole-shaped (with a value or two off), half anything."""
    width, height = draw(st.integers(-5, 5000)), draw(st.integers(-5, 5000))
    if draw(st.booleans()):
        return width, height, draw(st.lists(st.one_of(ANY_FLOAT, st.floats(0.0, 800.0)),
                                            min_size=0, max_size=10))
    fx, fy = draw(st.floats(1e-3, 5e3)), draw(st.floats(1e-3, 5e3))
    k = [fx, draw(st.one_of(st.just(0.0), st.floats(-10, 10))),
         draw(st.floats(0.0, max(width, 1))), 0.0, fy, draw(st.floats(0.0, max(height, 1))),
         0.0, 0.0, 1.0]
    for _ in range(draw(st.integers(0, 2))):
        k[draw(st.integers(0, 8))] = draw(ANY_FLOAT)
    return width, height, k


@SETTINGS
@given(info=camera_infos())
def test_camera_info_is_refused_or_makes_a_camera_whose_rays_are_finite(info):
    width, height, k = info
    problem = intrinsics_problem(width, height, k)
    event('refused' if problem else 'taken')
    if problem:
        return
    camera = CameraModel(np.asarray(k, float).reshape(3, 3), np.eye(3), np.zeros(3))
    for u, v in ((0.0, 0.0), (width / 2, height / 2), (width - 1.0, height - 1.0)):
        ray = camera.ray(u, v)
        assert np.all(np.isfinite(ray)) and ray[2] > 0.0


YOUBOT = YoubotKinematics()


@st.composite
def poses(draw):
    if draw(st.booleans()):                  # reachable: the pose of random joint positions
        q = np.array([draw(st.floats(lo + 0.05, hi - 0.05))
                      for lo, hi in zip(YOUBOT.lower, YOUBOT.upper)])
        return YOUBOT.fk(q)
    pose = np.eye(4)
    pose[:3, 3] = [draw(ANY_FLOAT) for _ in range(3)]
    if draw(st.booleans()):
        pose[draw(st.integers(0, 3)), draw(st.integers(0, 3))] = draw(ANY_FLOAT)
    return pose


@settings(SETTINGS, max_examples=150)
@given(pose=poses(), execute=st.sampled_from([True, True, True, False]),
       duration=st.one_of(st.just(0.0), st.just(0.0), st.floats(0.0, 20.0), ANY_FLOAT),
       scaling=st.one_of(st.just(0.0), st.floats(0.0, 1.0), ANY_FLOAT),
       seed=st.one_of(st.none(), st.none(), st.lists(ANY_FLOAT, min_size=0, max_size=6)))
def test_an_ik_request_is_answered_and_a_planned_motion_is_one_the_simulator_takes(
        pose, execute, duration, scaling, seed):
    current = np.zeros(len(YOUBOT.joint_names))
    plan = plan_ik(YOUBOT, pose, execute, duration, scaling, current, seed)
    event('refused' if not plan.success else 'solved' if plan.duration is None else 'planned')
    if not plan.success:
        assert plan.message
        return
    assert np.all(np.isfinite(plan.positions))
    assert np.all(plan.positions >= YOUBOT.lower - 1e-9)
    assert np.all(plan.positions <= YOUBOT.upper + 1e-9)
    if plan.duration is None:
        return
    assert 0.0 < plan.duration <= MAX_MOTION_S
    limits = JointLimits(YOUBOT.lower, YOUBOT.upper, YOUBOT.velocity_limits,
                         np.ones(len(current)))
    follower = TrajectoryFollower(YOUBOT.joint_names, limits, current)
    accepted = follower.set_trajectory(TrajectoryRequest(
        YOUBOT.joint_names, (TrajectoryPoint(plan.duration, tuple(plan.positions)),)), 0.0)
    assert accepted.accepted, accepted.reason


# Any JSON value, the panel's own words often among them.
JSON_LEAVES = st.one_of(st.none(), st.booleans(), st.integers(), st.integers(-10 ** 30, 10 ** 30),
                        ANY_FLOAT, st.text(max_size=20),
                        st.sampled_from(_OPS + tuple(MOTIONS) + ('/mini_robot', '', 'op')))
JSON_VALUES = json_values(JSON_LEAVES)


# What each field of a command holds when a page means well.
GOOD_FIELDS = {'motion': st.sampled_from(tuple(MOTIONS)), 'fraction': st.floats(0.0, 1.0),
               'namespace': st.sampled_from(['/mini_robot', '/youbot', '']),
               'on': st.booleans(), 'extra': JSON_VALUES}


@st.composite
def page_messages(draw):
    """What a page could send: a command with good or any fields, any JSON (NaN and Infinity
    among it), deep nesting, bytes, or any text at all."""
    kind = draw(st.sampled_from(['command', 'command', 'command', 'json', 'text', 'deep',
                                 'bytes']))
    if kind == 'command':
        message = {'op': draw(st.one_of(st.sampled_from(_OPS), st.sampled_from(_OPS),
                                        JSON_VALUES))}
        own = {'hold': 'motion', 'speed': 'fraction', 'select': 'namespace',
               'report_turns': 'on'}.get(message['op']) if isinstance(message['op'], str) \
            else None
        if own is not None and draw(st.booleans()):
            message[own] = draw(GOOD_FIELDS[own])
        for key in draw(st.lists(st.sampled_from(sorted(GOOD_FIELDS)), max_size=3)):
            message[key] = draw(st.one_of(GOOD_FIELDS[key], GOOD_FIELDS[key], JSON_VALUES))
        return json.dumps(message)
    if kind == 'json':
        return json.dumps(draw(JSON_VALUES))
    if kind == 'deep':
        depth = draw(st.integers(1, 5000))
        return draw(st.sampled_from(['[', '{"a":'])) * depth
    if kind == 'bytes':
        return draw(st.binary(max_size=64))
    return draw(st.text(max_size=200))


@pytest.mark.slow
@settings(SETTINGS, max_examples=600)
@given(message=page_messages())
def test_whatever_a_page_sends_is_a_valid_command_or_a_reason(message):
    """The control panel's one gate: never another exception (a traceback that closed the
    page's connection), and what it lets through is a command the dead man can take."""
    try:
        cmd = parse_command(message)
    except PanelInputError as exc:
        event('refused')
        assert str(exc)
        assert len(str(exc)) < 300
        return
    event(f'accepted {cmd.op}')
    assert isinstance(message, str) and len(message) <= MAX_MESSAGE_BYTES
    assert cmd.op in _OPS
    if cmd.op == 'hold':
        assert cmd.motion in MOTIONS and cmd.motion != 'stop'
    if cmd.op == 'speed':
        assert isinstance(cmd.fraction, float) and 0.0 <= cmd.fraction <= 1.0
    if cmd.op == 'select':
        assert isinstance(cmd.namespace, str)
    assert isinstance(cmd.on, bool)
