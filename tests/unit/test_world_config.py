"""World YAML loading and its error messages."""
import pytest

from world_description.resources import resolve_resource
from world_description.world_config import (
    MAX_WORLD_BYTES,
    WorldConfigError,
    load_world,
    parse_world,
)

ROBOT = {'name': 'r1', 'urdf': 'package://robot_description/urdf/mini_robot.urdf'}


def test_default_world_loads():
    cfg = load_world(resolve_resource('package://world_description/worlds/mini_robot.yaml'))
    robot = cfg.robot('mini_robot')
    assert robot.namespace == 'mini_robot'
    assert robot.drive.wheel_radius == 0.03 and robot.drive.wheel_separation == 0.113
    assert len(cfg.obstacles) >= 3
    cam = cfg.cameras[0]
    assert (cam.width, cam.height, cam.rate) == (320, 240, 15.0)
    assert cam.frame_id == 'camera_optical_frame'


def test_defaults_and_frame_prefix():
    cfg = parse_world({'robots': [dict(ROBOT, frame_prefix='r1/')],
                       'cameras': [{'name': 'cam', 'robot': 'r1', 'link': 'camera_link'}]})
    assert cfg.robots[0].namespace == 'r1'
    assert cfg.cameras[0].frame_id == 'r1/camera_link'


@pytest.mark.parametrize('data, fragment', [
    ([], 'mapping'),
    ({'robots': [{'name': 'r1'}]}, 'urdf is required'),
    ({'robots': [dict(ROBOT, colour=1)]}, 'unknown keys'),
    ({'robots': [ROBOT, ROBOT]}, 'unique'),
    ({'robots': [dict(ROBOT, name='1bad')]}, 'ROS name'),
    ({'robots': [dict(ROBOT, pose={'x': 'far'})]}, 'must be a number'),
    ({'robots': [dict(ROBOT, pose={'yaw': float('nan')})]}, 'finite'),
    ({'robots': [dict(ROBOT, drive={'type': 'tracked'})]}, '"diff_drive" or "mecanum"'),
    ({'robots': [dict(ROBOT, drive={'type': 'mecanum'})]}, 'wheel_joints must list 4'),
    ({'robots': [dict(ROBOT, drive={'type': 'mecanum', 'wheel_joints': ['a', 'b', 'c', 'd'],
                                    'wheel_radius': 0.05, 'wheel_effort': 5})]},
     'sum_of_robot_center_projection_on_X_Y_axis is required'),
    ({'robots': [dict(ROBOT, drive={'type': 'mecanum', 'wheel_joints': ['a', 'b', 'c', 'd'],
                                    'wheel_radius': 0.05, 'wheel_effort': 5,
                                    'sum_of_robot_center_projection_on_X_Y_axis': 0.4,
                                    'max_accel': -1.0})]}, 'max_accel'),
    ({'robots': [dict(ROBOT, controllers=[{'name': 'arm', 'joints': []}])]},
     'joints must be a non-empty list'),
    ({'robots': [dict(ROBOT, controllers=[{'name': 'arm', 'joints': ['a', 'a']}])]},
     'has duplicates'),
    ({'robots': [dict(ROBOT, controllers=[{'name': 'arm', 'joints': ['a']},
                                          {'name': 'arm', 'joints': ['b']}])]},
     'names must be unique'),
    ({'robots': [dict(ROBOT, controllers=[{'name': 'arm', 'joints': ['a', 'b']},
                                          {'name': 'hand', 'joints': ['b']}])]},
     'a joint belongs to two controllers or to a controller and the drive'),
    ({'robots': [dict(ROBOT, initial_joint_positions={'a': 'up'})]}, 'must be a number'),
    ({'obstacles': [{'shape': 'cone', 'size': [1], 'position': [0, 0, 0]}]}, 'shape'),
    ({'obstacles': [{'shape': 'box', 'size': [1, 1], 'position': [0, 0, 0]}]}, '3 numbers'),
    ({'cameras': [{'name': 'c', 'robot': 'ghost', 'link': 'x'}]}, 'not a robot'),
    ({'cameras': [{'name': 'c', 'position': [0, 0, 1], 'look_at': [0, 0, 1]}]}, 'coincide'),
    ({'cameras': [{'name': 'c', 'position': [0, 0, 1], 'look_at': [0, 0, 0],
                   'width': 0}]}, 'width'),
    ({'cameras': [{'name': 'c', 'position': [0, 0, 1], 'look_at': [0, 0, 0], 'near': 2,
                   'far': 1}]}, 'far must be greater'),
])
def test_bad_worlds_are_rejected_with_the_field_named(data, fragment):
    with pytest.raises(WorldConfigError, match=fragment):
        parse_world(data, 'test.yaml')


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(WorldConfigError, match='does not exist'):
        load_world(tmp_path / 'nope.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('robots: [unclosed')
    with pytest.raises(WorldConfigError, match='not valid YAML'):
        load_world(bad)
    latin = tmp_path / 'latin.yaml'                # (issue 15, finding 7: was a traceback)
    latin.write_bytes('robots: []  # caf\xe9\n'.encode('latin-1'))
    with pytest.raises(WorldConfigError, match='not UTF-8 text'):
        load_world(latin)


def test_a_world_path_that_is_not_a_world_file_is_named_for_what_it_is(tmp_path):
    with pytest.raises(WorldConfigError, match='is a directory'):
        load_world(tmp_path)
    (tmp_path / 'a.yaml').symlink_to(tmp_path / 'b.yaml')
    (tmp_path / 'b.yaml').symlink_to(tmp_path / 'a.yaml')
    with pytest.raises(WorldConfigError, match='Too many levels of symbolic links'):
        load_world(tmp_path / 'a.yaml')
    big = tmp_path / 'big.yaml'                   # (a 1 GB world took 8.5 min to parse)
    with open(big, 'wb') as f:
        f.truncate(MAX_WORLD_BYTES + 1)
    with pytest.raises(WorldConfigError, match='a world file is at most'):
        load_world(big)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('robots:\n  - name: [\n')
    with pytest.raises(WorldConfigError) as error:
        load_world(bad)
    assert '\n' not in str(error.value) and 'at line 3' in str(error.value)


def test_both_bases_have_acceleration_limits():
    for world in ('youbot', 'pipeline_cell'):
        cfg = load_world(resolve_resource(f'package://world_description/worlds/{world}.yaml'))
        limits = cfg.robot('youbot').limits
        assert (limits.max_accel, limits.max_turn_accel) == (1.0, 2.0)
    mini = load_world(resolve_resource('package://world_description/worlds/mini_robot.yaml'))
    limits = mini.robot('mini_robot').limits
    assert (limits.max_accel, limits.max_turn_accel) == (1.0, 2.0)


def test_the_joint_limits_files_match_what_the_planner_plans_with(tmp_path):
    """robot_description/config/*_joint_limits.yaml (MoveIt's format) are what the simulator
    refuses trajectories by; the pipeline plans with controllers' constants: the same."""
    from controllers import youbot_arm, zu12_arm
    from world_description.joint_limits import JointLimitsError, load_acceleration_limits
    youbot = load_acceleration_limits(resolve_resource(
        'package://robot_description/config/youbot_joint_limits.yaml'))
    assert [youbot[j] for j in youbot_arm.JOINT_NAMES] == [youbot_arm.JOINT_ACCELERATION_LIMIT] * 5
    zu12 = load_acceleration_limits(resolve_resource(
        'package://robot_description/config/zu12_joint_limits.yaml'))
    assert tuple(zu12[j] for j in zu12_arm.JOINT_NAMES) == zu12_arm.JOINT_ACCELERATION_LIMITS
    cell = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
    arms = [c for r in cell.robots for c in r.controllers if c.name == 'arm_controller']
    assert [c.path_tolerance for c in arms] == [0.25, 0.25] and all(c.joint_limits for c in arms)
    for text, why in [('joint_limits: 3', 'needs a "joint_limits" mapping'),
                      ('joint_limits: {a: {has_acceleration_limits: true}}', 'max_acceleration'),
                      ('joint_limits: {a: {has_acceleration_limits: true, max_acceleration: -1}}',
                       r'within \(0, 10000\]'),
                      ('joint_limits: {a: {has_acceleration_limits: 1}}', 'true or false'),
                      ('{', 'cannot be read as YAML')]:
        bad = tmp_path / 'bad.yaml'
        bad.write_text(text)
        with pytest.raises(JointLimitsError, match=why):
            load_acceleration_limits(bad)
    with pytest.raises(JointLimitsError, match='cannot be read'):
        load_acceleration_limits(tmp_path / 'missing.yaml')
    off = tmp_path / 'off.yaml'
    off.write_text('joint_limits: {a: {has_acceleration_limits: false, max_acceleration: 3}}')
    assert load_acceleration_limits(off) == {}


def _numbers(data, path=()):
    """Every number of a world's data (not a boolean), by its path of keys and indices."""
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _numbers(value, path + (key,))
    elif isinstance(data, list):
        for i, value in enumerate(data):
            yield from _numbers(value, path + (i,))
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        yield path


def _set(data, path, value):
    import copy
    out = copy.deepcopy(data)
    node = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


@pytest.mark.parametrize('world', ['pipeline_cell', 'pipeline_cell_perturbed',
                                   'cell_four_classes', 'youbot', 'mini_robot'])
def test_every_number_of_a_world_has_a_range(world):
    """Issue 47: gravity=1e300 was taken (materials flew to 2,760 m), and robot poses and
    initial joint positions alike. Each number of a world, set far out either way, is refused
    with the field named."""
    import yaml

    from world_description.world_config import parse_world, world_data
    data = world_data(resolve_resource(f'package://world_description/worlds/{world}.yaml'))
    data.pop('perturbations', None) if world != 'pipeline_cell_perturbed' else None
    paths = list(_numbers(data))
    assert len(paths) > 20
    for path in paths:
        for value in (1e300, -1e300):
            with pytest.raises(WorldConfigError) as raised:
                parse_world(_set(data, path, value), 'w.yaml')
            assert str(path[-1]) in str(raised.value) or 'w.yaml' in str(raised.value), path
    assert yaml.safe_dump(data)      # (the unchanged world still loads)
    parse_world(data, 'w.yaml')


def test_a_world_whose_aliases_expand_past_reason_is_refused(tmp_path):
    """The "billion laughs" in YAML: 1 kB of anchors and aliases for 10^9 values, which a
    result's or a bag's copy of the world would write out."""
    lines = ['a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]']
    lines += [f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * 10) + ']' for k in range(1, 9)]
    path = tmp_path / 'laughs.yaml'
    path.write_text('\n'.join(lines) + '\ngravity: -9.81\n')
    with pytest.raises(WorldConfigError, match='aliases are expanded'):
        load_world(path)
