"""The world's entities as the simulation interfaces see them (sim_bridge/entities.py, no ROS):
listed and filtered, their states read and set, spawned and deleted, with a clear refusal for
what cannot be done."""
import math
import os
from pathlib import Path

import numpy as np
import pytest

from sim_bridge.entities import Entities
from sim_bridge.entity_types import (
    DYNAMIC_OBJECT,
    ROBOT,
    STATIC_OBJECT,
    EntityError,
    Filters,
    Info,
    State,
)
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.spawning import named_poses
from sim_bridge.world import SimWorld
from world_description.resources import resolve_resource
from world_description.world_config import load_world

WORLD = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
UPRIGHT = (0.0, 0.0, 0.0, 1.0)


@pytest.fixture
def cell():
    world = SimWorld(WORLD)
    runner = SimRunner(world, DriveLimits(), 100.0)
    entities = Entities(world, lambda: world.sim_time)
    yield world, runner, entities
    entities.spawner.close()
    world.close()


def _run(world, runner, seconds):
    runner.advance(round(seconds / world.time_step), NullSink())


def _error(code, call, *args, **kwargs):
    with pytest.raises(EntityError) as raised:
        call(*args, **kwargs)
    assert raised.value.code == code, str(raised.value)
    return str(raised.value)


def test_the_cell_lists_its_robots_materials_and_scene(cell):
    world, runner, entities = cell
    names = entities.names()
    assert {'zu12', 'youbot', 'floor', 'conveyor', 'conveyor_end_stop', 'ground_target',
            'pool_floor', 'pool_platform'} <= set(names)
    assert not [n for n in names if n.startswith('material_')]      # none dropped yet
    _run(world, runner, 6.0)
    materials = entities.names(Filters(pattern='^material_'))
    assert materials and materials == [f'material_{m.index}' for m in world.materials]
    # Filters: categories, tags (any or all), an overlap with a sphere or a box.
    assert entities.names(Filters(categories=(ROBOT,))) == ['zu12', 'youbot']
    assert entities.names(Filters(tags=('mobile', 'fixed_base'))) == ['zu12', 'youbot']
    assert entities.names(Filters(tags=('robot', 'mecanum'), all_tags=True)) == ['youbot']
    near_pool = entities.names(Filters(sphere=((2.1, -1.3, 0.0), 0.1)))
    assert 'pool_floor' in near_pool and 'youbot' not in near_pool
    assert 'youbot' in entities.names(Filters(box=((0.7, -0.1, 0.0), (0.9, 0.2, 0.3))))
    assert 'regular expression' in _error('failed', entities.names, Filters(pattern='(['))


def test_a_state_is_the_canonical_frame_in_the_world(cell):
    world, runner, entities = cell
    youbot = entities.state('youbot')
    assert youbot.position == pytest.approx((0.8, 0.05, 0.0815), abs=2e-3)
    # Facing -y: yaw -90 degrees.
    x, y, z, w = youbot.orientation
    assert math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)) == pytest.approx(
        -math.pi / 2, abs=1e-3)
    assert entities.state('zu12').position == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    _error('not_found', entities.state, 'nobody')


def test_moving_a_mobile_robot_and_a_material(cell):
    world, runner, entities = cell
    entities.set_state('youbot', State((1.2, -0.5, 0.0815), UPRIGHT))
    _run(world, runner, 0.2)
    assert entities.state('youbot').position[:2] == pytest.approx((1.2, -0.5), abs=5e-3)
    # Its odometry follows (ground truth in the odom frame of its start pose).
    base = world.robots['youbot'].sensors.base_state()
    assert math.hypot(*base.position[:2]) == pytest.approx(math.hypot(0.4, 0.55), abs=5e-3)
    # In another entity's frame: 1 m ahead of the youBot.
    entities.set_state('youbot', State((0.0, 0.0, 0.0815), UPRIGHT))
    entities.set_state('youbot', State((1.0, 0.0, 0.0), UPRIGHT), frame='youbot')
    assert entities.state('youbot').position[:2] == pytest.approx((1.0, 0.0), abs=5e-3)
    # What cannot move says why.
    assert 'fixed to the world' in _error('failed', entities.set_state, 'zu12',
                                          State((0.0, 1.0, 0.0), UPRIGHT))
    assert 'fixed scene' in _error('failed', entities.set_state, 'conveyor',
                                   State((0.0, 1.0, 0.0), UPRIGHT))
    _error('invalid_pose', entities.set_state, 'youbot', State((0.0, 0.0, 0.1), (0, 0, 0, 0)))
    _error('invalid_pose', entities.set_state, 'youbot',
           State((math.nan, 0.0, 0.1), UPRIGHT))
    _error('invalid_pose', entities.set_state, 'youbot', State((0.0, 0.0, 0.1), UPRIGHT),
           frame='nowhere')


def test_spawned_shapes_fall_and_are_deleted(cell):
    world, runner, entities = cell
    spawner = entities.spawner
    name = entities.spawner.spawn('crate', False,
                                  'shape://box?size=0.2,0.1,0.1&mass=1&color=blue', '', '',
                                  State((1.5, 1.5, 0.5), UPRIGHT))
    assert name == 'crate' and entities.info('crate').category == DYNAMIC_OBJECT
    _run(world, runner, 1.5)
    assert entities.state('crate').position[2] == pytest.approx(0.05, abs=3e-3)   # on the floor
    lo, hi = entities.bounds('crate')
    assert hi == pytest.approx((0.1, 0.05, 0.05)) and lo == pytest.approx((-0.1, -0.05, -0.05))
    # A static post, a taken name, renaming, a shape inside another body.
    post = entities.spawner.spawn('post', False,
                                  'shape://cylinder?radius=0.05&length=0.4&mass=0', '', '',
                                  State((1.5, 1.0, 0.2), UPRIGHT))
    assert entities.info(post).category == STATIC_OBJECT
    assert 'static' in _error('failed', entities.set_state, post,
                              State((1.5, 1.0, 0.2), UPRIGHT, (0.1, 0.0, 0.0)))
    _error('name_not_unique', spawner.spawn, 'crate', False, 'shape://sphere?radius=0.05', '',
           '', State((1.5, 2.0, 0.5), UPRIGHT))
    again = entities.spawner.spawn('crate', True, 'shape://sphere?radius=0.05', '', '',
                                   State((1.5, 2.0, 0.5), UPRIGHT))
    assert again == 'crate_1'
    assert 'inside' in _error('invalid_pose', spawner.spawn, 'buried', False,
                              'shape://box?size=0.3,0.3,0.3', '', '',
                              State((1.5, 1.5, 0.0), UPRIGHT))
    assert 'buried' not in entities.names()
    _error('name_invalid', spawner.spawn, 'material_99', False, 'shape://sphere?radius=0.05',
           '', '', State((1.5, 2.5, 0.5), UPRIGHT))
    _error('failed', spawner.spawn, 'x', False, 'shape://box?size=0.1,0.1', '', '',
           State((1.5, 2.5, 0.5), UPRIGHT))
    _error('unsupported_format', spawner.spawn, 'x', False, 'shape://cone?radius=1', '', '',
           State((1.5, 2.5, 0.5), UPRIGHT))
    _error('no_resource', spawner.spawn, 'x', False, '', '', '', State((1, 2, 0.5), UPRIGHT))
    _error('namespace_invalid', spawner.spawn, 'x', False, 'shape://sphere?radius=0.05', '',
           'bad ns', State((1.5, 2.5, 0.5), UPRIGHT))
    entities.delete('crate')
    assert 'crate' not in entities.names()
    assert 'robot' in _error('failed', entities.delete, 'youbot')
    assert 'fixed scene' in _error('failed', entities.delete, 'pool_floor')
    assert sorted(entities.delete_spawned()) == ['crate_1', 'post']


def test_a_spawned_material_rides_the_belt_and_is_one_of_the_cells(cell):
    world, runner, entities = cell
    spawner = entities.spawner
    drop = next(p for p in named_poses(world) if p.name == 'belt_drop')
    _run(world, runner, 1.0)             # (the plan's first material drops there at the start)
    name = entities.spawner.spawn('extra', False, 'material://orange', '', '', drop.pose)
    material = next(m for m in world.materials if m.name == 'extra')
    assert material.color == 'orange' and 'material' in entities.info(name).tags
    start = entities.state(name).position
    _run(world, runner, 2.0)
    moved = np.subtract(entities.state(name).position, start)
    speed = world.conveyor.speed
    assert moved[0] == pytest.approx(2.0 * speed, rel=0.05) and abs(moved[1]) < 1e-3
    # The plan's materials keep their ids (the spawned one takes the next free index).
    assert [m.index for m in world.materials] == sorted(m.index for m in world.materials)
    _error('not_found', spawner.spawn, 'x', False, 'material://green', '', '', drop.pose)
    entities.delete(name)
    assert material not in world.materials


def test_a_urdf_spawns_from_a_package_a_file_or_its_text(cell, tmp_path):
    world, runner, entities = cell
    spawner = entities.spawner
    name = entities.spawner.spawn('', True, 'package://robot_description/urdf/mini_robot.urdf', '',
                                  '', State((2.0, 2.0, 0.1), UPRIGHT))
    assert name.startswith('mini_robot')
    urdf = tmp_path / 'block.urdf'
    urdf.write_text('<robot name="block"><link name="base"><inertial><mass value="1"/>'
                    '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
                    '</inertial><collision><geometry><box size="0.1 0.1 0.1"/></geometry>'
                    '</collision></link></robot>')
    assert entities.spawner.spawn('b1', False, f'file://{urdf}', '', '',
                                  State((2.5, 2.0, 0.3), UPRIGHT)) == 'b1'
    assert entities.spawner.spawn('b2', False, '', urdf.read_text(), '',
                                  State((2.5, 2.5, 0.3), UPRIGHT)) == 'b2'
    _run(world, runner, 1.0)
    assert entities.state('b2').position[2] == pytest.approx(0.05, abs=3e-3)
    _error('not_found', spawner.spawn, 'x', False, f'file://{tmp_path}/none.urdf', '', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('unsupported_format', spawner.spawn, 'x', False, 'model.sdf', '', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('parse_error', spawner.spawn, 'x', False, '', 'not a urdf', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('parse_error', spawner.spawn, 'x', False, '', '<robot name="r"><link', '',
           State((3.0, 3.0, 0.3), UPRIGHT))


def test_a_reset_of_the_state_puts_spawned_bodies_back(cell):
    world, runner, entities = cell
    entities.spawner.spawn('ball', False, 'shape://sphere?radius=0.05&mass=0.2', '', '',
                           State((1.5, 1.5, 0.5), UPRIGHT))
    _run(world, runner, 1.0)
    assert entities.state('ball').position[2] < 0.1
    runner.reset()
    entities.reset_spawned()
    assert entities.state('ball').position == pytest.approx((1.5, 1.5, 0.5), abs=1e-6)


def test_spawnables_and_named_poses(cell):
    world, runner, entities = cell
    uris = [s.uri for s in entities.spawner.spawnables()]
    assert {'material://purple', 'material://orange', 'material://blue'} <= set(uris)
    assert 'package://robot_description/urdf/youbot.urdf' in uris
    poses = {p.name: p for p in named_poses(world)}
    assert {'ground_target', 'pool_floor', 'pool_platform', 'youbot_start', 'zu12_start',
            'belt_drop'} <= set(poses)
    assert poses['pool_floor'].pose.position == pytest.approx((2.1, -1.3, 0.002))
    lo, hi = poses['pool_floor'].box
    assert lo[:2] == pytest.approx((1.8, -1.6)) and hi[:2] == pytest.approx((2.4, -1.0))


# --- requests from a careless or hostile client (issue 47): each answered at once ---------------
def test_a_name_filter_runs_in_linear_time_and_its_limits_say_why(cell):
    """Python's re took minutes on this pattern against the cell's names (it backtracks);
    RE2 reads each name once. POSIX classes (the standard's syntax) work; what RE2 cannot
    do (a backreference) is refused with the reason."""
    world, runner, entities = cell
    assert entities.names(Filters(pattern=r'(\w*\w*\w*\w*\w*\w*\w*\w*)*!')) == []
    assert entities.names(Filters(pattern='^[[:alpha:]]+12$')) == ['zu12']
    assert 'RE2' in _error('failed', entities.names, Filters(pattern=r'(a)\1'))
    assert 'at most' in _error('failed', entities.names, Filters(pattern='a' * 2000))
    assert 'tags' in _error('failed', entities.names, Filters(tags=('t',) * 100))


def test_a_urdf_text_is_checked_before_pybullet_reads_it_and_leaves_no_file(cell, tmp_path):
    from sim_bridge.entity_types import SCRATCH_PREFIX
    from world_description.urdf_check import MAX_LINKS, MAX_URDF_BYTES
    world, runner, entities = cell
    spawner = entities.spawner
    scratch = entities.spawner._scratch.path
    here = State((3.0, 3.0, 0.3), UPRIGHT)
    # 315 kB of "<robot ": a regular expression over the text took two minutes; expat
    # stops at its first malformed byte.
    assert 'not well-formed' in _error('parse_error', spawner.spawn, 'x', False, '',
                                       '<robot ' * 45_000, '', here)
    assert 'bytes' in _error('parse_error', spawner.spawn, 'x', False, '',
                             '<robot name="r">' + ' ' * MAX_URDF_BYTES + '</robot>', '', here)
    laughs = ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">'
              '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><robot name="r">&b;</robot>')
    assert 'document type' in _error('parse_error', spawner.spawn, 'x', False, '', laughs,
                                     '', here)
    links = ''.join(f'<link name="l{k}"/>' for k in range(MAX_LINKS + 1))
    assert 'links' in _error('parse_error', spawner.spawn, 'x', False, '',
                             f'<robot name="r">{links}</robot>', '', here)
    fifo = tmp_path / 'pipe.obj'
    os.mkfifo(fifo)
    for mesh, code in ((str(fifo), 'not_found'), ('/nowhere/m.obj', 'not_found'),
                       ('relative.obj', 'not_found'), ('/dev/zero', 'unsupported_format')):
        text = (f'<robot name="m"><link name="b"><visual><geometry><mesh filename="{mesh}"/>'
                '</geometry></visual></link></robot>')
        _error(code, spawner.spawn, 'x', False, '', text, '', here)
    big = tmp_path / 'big.urdf'
    big.write_text('<robot name="big">' + ' ' * MAX_URDF_BYTES + '</robot>')
    _error('parse_error', spawner.spawn, 'x', False, f'file://{big}', '', '', here)
    block = ('<robot name="block"><link name="base"><inertial><mass value="1"/>'
             '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
             '<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>'
             '</robot>')
    assert entities.spawner.spawn('', True, '', block, '', here).startswith('block')
    assert [p.name for p in scratch.iterdir()] == ['.owner.lock']   # nothing else kept
    assert scratch.name.startswith(SCRATCH_PREFIX)
    entities.spawner.close()
    assert not scratch.exists()


def test_a_scratch_directory_of_a_dead_run_is_removed_by_the_next(tmp_path):
    """A SIGKILLed simulator cannot remove its scratch directory: the next one does, and
    leaves a living one's alone."""
    import subprocess
    import sys

    from sim_bridge.scratch import ScratchDir
    code = ('import sys, time; from pathlib import Path; from sim_bridge.scratch import '
            'ScratchDir; s = ScratchDir("sim_x_", Path(sys.argv[1])); '
            '(s.path / "left.urdf").write_text("x"); print(s.path, flush=True); time.sleep(60)')
    dead = subprocess.Popen([sys.executable, '-c', code, str(tmp_path)], stdout=subprocess.PIPE,
                            text=True)
    dead_dir = Path(dead.stdout.readline().strip())
    dead.kill()
    dead.wait()
    alive = ScratchDir('sim_x_', tmp_path)
    assert dead_dir.exists() is False and alive.removed_stale == [dead_dir]
    again = ScratchDir('sim_x_', tmp_path)
    assert alive.path.exists() and again.removed_stale == []
    alive.close()
    again.close()
    assert list(tmp_path.iterdir()) == []


def test_spawned_entities_are_bounded_in_number_and_size_of_request(cell):
    from sim_bridge.entity_types import MAX_NAME_CHARS, MAX_SPAWNED
    world, runner, entities = cell
    spawner = entities.spawner
    for k in range(MAX_SPAWNED):
        entities.spawner.spawn(f'b{k}', False, 'shape://box?size=0.02,0.02,0.02&mass=0', '',
                               '', State((-1.0 + (k % 20) * 0.05, 2.0 + (k // 20) * 0.05, 0.5),
                                         UPRIGHT))
    assert 'at most' in _error('failed', spawner.spawn, 'one_more', False,
                               'shape://sphere?radius=0.01', '', '',
                               State((3.0, -2.0, 0.5), UPRIGHT))
    entities.delete('b0')
    entities.spawner.spawn('one_more', False, 'shape://sphere?radius=0.01', '', '',
                           State((3.0, -2.0, 0.5), UPRIGHT))
    _error('name_invalid', spawner.spawn, 'n' * (MAX_NAME_CHARS + 1), False,
           'shape://sphere?radius=0.01', '', '', State((3.0, -2.5, 0.5), UPRIGHT))
    assert 'at most' in _error('failed', entities.set_info, 'youbot',
                               Info(ROBOT, 'd' * 5000, []))


@pytest.mark.parametrize('linear, angular', [((1e300, 0.0, 0.0), (0.0, 0.0, 0.0)),
                                             ((60.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                                             ((0.0, 0.0, 0.0), (0.0, 0.0, 60.0))])
def test_a_state_set_from_outside_is_held_to_speed_limits(cell, linear, angular):
    world, runner, entities = cell
    spawner = entities.spawner
    entities.spawner.spawn('ball', False, 'shape://sphere?radius=0.05&mass=0.2', '', '',
                           State((1.5, 1.5, 0.5), UPRIGHT))
    assert 'velocity' in _error('invalid_pose', entities.set_state, 'ball',
                                State((1.5, 1.5, 0.5), UPRIGHT, linear, angular))
    assert 'velocity' in _error('invalid_pose', spawner.spawn, 'thrown', False,
                                'shape://sphere?radius=0.05&mass=0.2', '', '',
                                State((1.5, 2.5, 0.5), UPRIGHT, linear, angular))
    entities.set_state('ball', State((1.5, 1.5, 0.5), UPRIGHT, (10.0, 0.0, 0.0)))
    _run(world, runner, 0.05)
    assert entities.state('ball').linear[0] == pytest.approx(10.0, rel=0.05)


def test_a_body_whose_state_goes_wrong_is_taken_out_before_the_next_step(cell):
    """Whatever brings a free body's state to NaN or off into the distance (here PyBullet is
    told so directly, past every check), the step after which it happened takes it out: it is
    never stepped on, and never reported."""
    world, runner, entities = cell
    p = world.client
    entities.spawner.spawn('ball', False, 'shape://sphere?radius=0.05&mass=0.2', '', '',
                           State((1.5, 1.5, 0.5), UPRIGHT))
    entities.spawner.spawn('crate', False, 'shape://box?size=0.1,0.1,0.1&mass=1', '', '',
                           State((1.5, 2.0, 0.5), UPRIGHT))
    _run(world, runner, 3.0)                      # (a material is on the belt by now)
    material = world.materials[0]
    lost = []

    class Lost(NullSink):
        def on_body_lost(self, name, reason):
            lost.append((name, reason))
    ball = entities._get('ball').body
    p.resetBaseVelocity(ball, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0))
    runner.advance(1, Lost())
    taken = {name: what for name, what in lost if what.startswith('taken out')}
    assert list(taken) == ['ball'] and 'not finite' in taken['ball']
    assert 'ball' not in entities.names()
    _error('not_found', entities.state, 'ball')
    # Driven to PyBullet's velocity cap (it clamps, and simulates no more); a material far off.
    p.resetBaseVelocity(entities._get('crate').body, (5000.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    p.resetBasePositionAndOrientation(material.body, (2000.0, 0.0, 0.5), UPRIGHT)
    runner.advance(1, Lost())
    assert 'cap' in dict(lost)['crate'] and 'crate' not in entities.names()
    runner.advance(round(0.01 / world.time_step), Lost())      # (poses: at the state rate)
    assert 'origin' in dict(lost)[f'material_{material.index}']
    assert material not in world.materials
    # What is left is finite, and keeps working.
    for name in entities.names():
        state = entities.state(name)
        assert np.all(np.isfinite(state.position + state.linear))
    entities.spawner.spawn('crate', False, 'shape://box?size=0.1,0.1,0.1&mass=1', '', '',
                           State((1.5, 2.0, 0.5), UPRIGHT))
    _run(world, runner, 0.5)
    assert entities.state('crate').position[2] == pytest.approx(0.05, abs=3e-3)
