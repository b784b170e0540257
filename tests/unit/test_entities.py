"""The world's entities as the simulation interfaces see them (sim_bridge/entities.py, no ROS):
listed and filtered, their states read and set, spawned and deleted, with a clear refusal for
what cannot be done."""
import math

import numpy as np
import pytest

from sim_bridge.entities import (
    DYNAMIC_OBJECT,
    ROBOT,
    STATIC_OBJECT,
    Entities,
    EntityError,
    Filters,
    State,
)
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
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
    entities.close()
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
    base = world.robots['youbot'].base_state()
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
    name = entities.spawn('crate', False, 'shape://box?size=0.2,0.1,0.1&mass=1&color=blue', '',
                          '', State((1.5, 1.5, 0.5), UPRIGHT))
    assert name == 'crate' and entities.info('crate').category == DYNAMIC_OBJECT
    _run(world, runner, 1.5)
    assert entities.state('crate').position[2] == pytest.approx(0.05, abs=3e-3)   # on the floor
    lo, hi = entities.bounds('crate')
    assert hi == pytest.approx((0.1, 0.05, 0.05)) and lo == pytest.approx((-0.1, -0.05, -0.05))
    # A static post, a taken name, renaming, a shape inside another body.
    post = entities.spawn('post', False, 'shape://cylinder?radius=0.05&length=0.4&mass=0', '',
                          '', State((1.5, 1.0, 0.2), UPRIGHT))
    assert entities.info(post).category == STATIC_OBJECT
    assert 'static' in _error('failed', entities.set_state, post,
                              State((1.5, 1.0, 0.2), UPRIGHT, (0.1, 0.0, 0.0)))
    _error('name_not_unique', entities.spawn, 'crate', False, 'shape://sphere?radius=0.05', '',
           '', State((1.5, 2.0, 0.5), UPRIGHT))
    again = entities.spawn('crate', True, 'shape://sphere?radius=0.05', '', '',
                           State((1.5, 2.0, 0.5), UPRIGHT))
    assert again == 'crate_1'
    assert 'inside' in _error('invalid_pose', entities.spawn, 'buried', False,
                              'shape://box?size=0.3,0.3,0.3', '', '',
                              State((1.5, 1.5, 0.0), UPRIGHT))
    assert 'buried' not in entities.names()
    _error('name_invalid', entities.spawn, 'material_99', False, 'shape://sphere?radius=0.05',
           '', '', State((1.5, 2.5, 0.5), UPRIGHT))
    _error('failed', entities.spawn, 'x', False, 'shape://box?size=0.1,0.1', '', '',
           State((1.5, 2.5, 0.5), UPRIGHT))
    _error('unsupported_format', entities.spawn, 'x', False, 'shape://cone?radius=1', '', '',
           State((1.5, 2.5, 0.5), UPRIGHT))
    _error('no_resource', entities.spawn, 'x', False, '', '', '', State((1, 2, 0.5), UPRIGHT))
    _error('namespace_invalid', entities.spawn, 'x', False, 'shape://sphere?radius=0.05', '',
           'bad ns', State((1.5, 2.5, 0.5), UPRIGHT))
    entities.delete('crate')
    assert 'crate' not in entities.names()
    assert 'robot' in _error('failed', entities.delete, 'youbot')
    assert 'fixed scene' in _error('failed', entities.delete, 'pool_floor')
    assert sorted(entities.delete_spawned()) == ['crate_1', 'post']


def test_a_spawned_material_rides_the_belt_and_is_one_of_the_cells(cell):
    world, runner, entities = cell
    drop = next(p for p in entities.named_poses() if p.name == 'belt_drop')
    _run(world, runner, 1.0)             # (the plan's first material drops there at the start)
    name = entities.spawn('extra', False, 'material://orange', '', '', drop.pose)
    material = next(m for m in world.materials if m.name == 'extra')
    assert material.color == 'orange' and 'material' in entities.info(name).tags
    start = entities.state(name).position
    _run(world, runner, 2.0)
    moved = np.subtract(entities.state(name).position, start)
    speed = world.conveyor.speed
    assert moved[0] == pytest.approx(2.0 * speed, rel=0.05) and abs(moved[1]) < 1e-3
    # The plan's materials keep their ids (the spawned one takes the next free index).
    assert [m.index for m in world.materials] == sorted(m.index for m in world.materials)
    _error('not_found', entities.spawn, 'x', False, 'material://green', '', '', drop.pose)
    entities.delete(name)
    assert material not in world.materials


def test_a_urdf_spawns_from_a_package_a_file_or_its_text(cell, tmp_path):
    world, runner, entities = cell
    name = entities.spawn('', True, 'package://robot_description/urdf/mini_robot.urdf', '',
                          '', State((2.0, 2.0, 0.1), UPRIGHT))
    assert name.startswith('mini_robot')
    urdf = tmp_path / 'block.urdf'
    urdf.write_text('<robot name="block"><link name="base"><inertial><mass value="1"/>'
                    '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
                    '</inertial><collision><geometry><box size="0.1 0.1 0.1"/></geometry>'
                    '</collision></link></robot>')
    assert entities.spawn('b1', False, f'file://{urdf}', '', '',
                          State((2.5, 2.0, 0.3), UPRIGHT)) == 'b1'
    assert entities.spawn('b2', False, '', urdf.read_text(), '',
                          State((2.5, 2.5, 0.3), UPRIGHT)) == 'b2'
    _run(world, runner, 1.0)
    assert entities.state('b2').position[2] == pytest.approx(0.05, abs=3e-3)
    _error('not_found', entities.spawn, 'x', False, f'file://{tmp_path}/none.urdf', '', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('unsupported_format', entities.spawn, 'x', False, 'model.sdf', '', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('parse_error', entities.spawn, 'x', False, '', 'not a urdf', '',
           State((3.0, 3.0, 0.3), UPRIGHT))
    _error('parse_error', entities.spawn, 'x', False, '', '<robot name="r"><link', '',
           State((3.0, 3.0, 0.3), UPRIGHT))


def test_a_reset_of_the_state_puts_spawned_bodies_back(cell):
    world, runner, entities = cell
    entities.spawn('ball', False, 'shape://sphere?radius=0.05&mass=0.2', '', '',
                   State((1.5, 1.5, 0.5), UPRIGHT))
    _run(world, runner, 1.0)
    assert entities.state('ball').position[2] < 0.1
    runner.reset()
    entities.reset_spawned()
    assert entities.state('ball').position == pytest.approx((1.5, 1.5, 0.5), abs=1e-6)


def test_spawnables_and_named_poses(cell):
    world, runner, entities = cell
    uris = [s.uri for s in entities.spawnables()]
    assert {'material://purple', 'material://orange', 'material://blue'} <= set(uris)
    assert 'package://robot_description/urdf/youbot.urdf' in uris
    poses = {p.name: p for p in entities.named_poses()}
    assert {'ground_target', 'pool_floor', 'pool_platform', 'youbot_start', 'zu12_start',
            'belt_drop'} <= set(poses)
    assert poses['pool_floor'].pose.position == pytest.approx((2.1, -1.3, 0.002))
    lo, hi = poses['pool_floor'].box
    assert lo[:2] == pytest.approx((1.8, -1.6)) and hi[:2] == pytest.approx((2.4, -1.0))
