"""The TF tree sim_node publishes (sim_bridge.frames), against the simulation's ground truth."""
from __future__ import annotations

from typing import Dict, List

import numpy as np
import pybullet
import pytest

from controllers.transforms import quaternion_to_matrix
from sim_bridge.frames import WORLD_FRAME, FrameTransform, WorldFrames
from sim_bridge.world import SimWorld
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world


def _matrix(t: FrameTransform) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = quaternion_to_matrix(t.rotation)
    out[:3, 3] = t.translation
    return out


def _in_world(transforms: List[FrameTransform]) -> Dict[str, np.ndarray]:
    """Every frame's pose in the world, by walking the tree from the root."""
    parent = {}
    for t in transforms:
        assert t.child not in parent, f'{t.child} has two parents'
        parent[t.child] = t
    poses = {WORLD_FRAME: np.eye(4)}

    def pose(frame: str) -> np.ndarray:
        if frame not in poses:
            assert frame in parent, f'{frame} is not connected to {WORLD_FRAME}'
            t = parent[frame]
            poses[frame] = pose(t.parent) @ _matrix(t)
        return poses[frame]

    for frame in parent:
        pose(frame)
    return poses


@pytest.fixture(scope='module')
def cell():
    world = SimWorld(load_world(resolve_resource(PIPELINE_CELL)), scenario_seed=5)
    yield world
    world.close()


def _move_everything(world: SimWorld, rng: np.random.Generator) -> None:
    for robot in world.robots.values():
        for j in robot.movable:
            world._p.resetJointState(robot.body, j, float(rng.uniform(-1.0, 1.0)))
        if not robot.config.fixed_base:
            x, y, z = robot.start_pose[0]
            world._p.resetBasePositionAndOrientation(
                robot.body, (x + 0.3, y - 0.2, z + 0.01),
                pybullet.getQuaternionFromEuler((0.0, 0.0, float(rng.uniform(-3, 3)))))


def test_the_cell_is_one_tree_under_world_with_no_shared_frame(cell):
    frames = WorldFrames(cell)
    transforms = frames.static() + [t for r in frames.robots for t in frames.moving(r)]
    poses = _in_world(transforms)
    for name, robot in frames.robots.items():
        prefix = cell.robots[name].config.frame_prefix
        assert prefix == f'{name}/'
        assert set(robot.link_frames) <= set(poses)
        assert all(f.startswith(prefix) for f in robot.link_frames)
    assert {'youbot/odom', 'youbot/base_link', 'youbot/gripper_tcp', 'zu12/base_link',
            'zu12/suction_tcp', 'belt_camera_optical_frame'} <= set(poses)
    # REP-105: a mobile base hangs from its odom frame, a fixed one from the world.
    parents = {t.child: t.parent for t in transforms}
    assert parents['youbot/base_link'] == 'youbot/odom'
    assert parents['youbot/odom'] == parents['zu12/base_link'] == WORLD_FRAME


def test_every_link_frame_composes_to_its_simulated_pose(cell):
    rng = np.random.default_rng(3)
    frames = WorldFrames(cell)
    for _ in range(3):
        _move_everything(cell, rng)
        transforms = frames.static() + [t for r in frames.robots for t in frames.moving(r)]
        poses = _in_world(transforms)
        for robot in cell.robots.values():
            prefix = robot.config.frame_prefix
            for link in robot.link_index:
                pos, rot = robot.link_world_pose(link)
                np.testing.assert_allclose(poses[prefix + link][:3, 3], pos, atol=1e-9)
                np.testing.assert_allclose(poses[prefix + link][:3, :3], rot, atol=1e-9)
    for robot in cell.robots.values():
        robot.reset()


def test_static_transforms_are_only_what_never_moves(cell):
    frames = WorldFrames(cell)
    before = frames.static()
    _move_everything(cell, np.random.default_rng(4))
    after = frames.static()
    # (PyBullet computes link frames in single precision: a fixed joint's transform read
    # back in another arm pose differs by about 1e-8.)
    for a, b in zip(before, after):
        assert (a.parent, a.child) == (b.parent, b.child)
        np.testing.assert_allclose(a.translation, b.translation, atol=1e-6)
        np.testing.assert_allclose(np.abs(np.dot(a.rotation, b.rotation)), 1.0, atol=1e-6)
    moving = {t.child for r in frames.robots for t in frames.moving(r)}
    assert not moving & {t.child for t in after}
    for robot in cell.robots.values():
        robot.reset()


def test_the_fixed_camera_frame_looks_at_its_target(cell):
    (camera,) = cell.cameras
    c = camera.config
    (anchor,) = [t for t in WorldFrames(cell).static() if t.child == c.frame_id]
    assert anchor.parent == WORLD_FRAME
    pose = _matrix(anchor)
    np.testing.assert_allclose(pose[:3, 3], c.position, atol=1e-12)
    look = np.subtract(c.look_at, c.position)
    np.testing.assert_allclose(pose[:3, 2], look / np.linalg.norm(look), atol=1e-9)


def test_without_link_transforms_only_the_base_moves(cell):
    frames = WorldFrames(cell)
    assert [(t.parent, t.child) for t in frames.moving('youbot', links=False)] == \
        [('youbot/odom', 'youbot/base_link')]
    assert frames.moving('zu12', links=False) == []


def test_each_robot_description_names_the_frames_the_tree_publishes(cell):
    import xml.etree.ElementTree as ET

    from robot_description import with_frame_prefix
    frames = WorldFrames(cell)
    for name, robot in cell.robots.items():
        prefix = robot.config.frame_prefix
        original = ET.fromstring(robot.urdf.read_text())
        urdf = ET.fromstring(with_frame_prefix(robot.urdf.read_text(), prefix))
        links = {link.get('name') for link in urdf.iter('link')}
        assert links == set(frames.robots[name].link_frames)
        ends = {e.get('link') for j in urdf.iter('joint') for e in j if e.tag in
                ('parent', 'child')}
        assert ends <= links
        # Joint names as joint_states gives them, without the prefix.
        assert [j.get('name') for j in urdf.iter('joint')] == \
            [j.get('name') for j in original.iter('joint')]


def test_launches_without_link_tf_give_each_robot_a_state_publisher_of_its_frames():
    import xml.etree.ElementTree as ET

    from sim_bringup.state_publishers import state_publishers
    publishers = dict(state_publishers(PIPELINE_CELL))
    assert sorted(publishers) == ['youbot', 'zu12']
    for ns, params in publishers.items():
        links = {link.get('name') for link in
                 ET.fromstring(params['robot_description']).iter('link')}
        assert f'{ns}/base_link' in links and all(n.startswith(f'{ns}/') for n in links)
        assert params['use_sim_time'] is True
