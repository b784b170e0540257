"""The published intrinsics must describe the images PyBullet actually renders."""
import math

import numpy as np
import pybullet
import pytest

from sim_bridge.camera import ImageBuffer, projection_matrix, view_matrix_from_optical
from world_description.camera_geometry import intrinsics_from_fov, look_at_rotation


def test_projection_matches_pybullet():
    ours = projection_matrix(320, 240, 60.0, 0.01, 5.0)
    theirs = pybullet.computeProjectionMatrixFOV(60.0, 320 / 240, 0.01, 5.0)
    assert ours == pytest.approx(theirs, rel=1e-6)


def test_view_matrix_matches_pybullet_look_at():
    eye, target = (1.0, -0.5, 0.8), (0.2, 0.3, 0.0)
    ours = view_matrix_from_optical(eye, look_at_rotation(eye, target))
    theirs = pybullet.computeViewMatrix(eye, target, (0, 0, 1))
    assert ours == pytest.approx(theirs, abs=1e-6)


def test_k_matrix():
    k = intrinsics_from_fov(640, 480, 90.0)
    assert k.fx == pytest.approx(240.0) and k.fy == pytest.approx(240.0)
    assert (k.cx, k.cy) == (320.0, 239.0)
    assert k.k[8] == 1.0 and k.p[3] == 0.0


@pytest.fixture(scope='module')
def client():
    cid = pybullet.connect(pybullet.DIRECT)
    yield cid
    pybullet.disconnect(cid)


@pytest.mark.parametrize('seed, width, height, fov', [
    (0, 320, 240, 60.0), (1, 320, 240, 60.0), (2, 640, 480, 45.0), (3, 321, 241, 70.0),
    (4, 200, 300, 60.0), (5, 320, 240, 90.0)])
def test_rendered_marker_lands_where_the_intrinsics_project_it(client, seed, width, height, fov):
    rng = np.random.default_rng(seed)
    eye = np.array([0.0, 0.0, 1.0])
    rot = look_at_rotation(eye, (rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 0.0))
    # A small red sphere somewhere in view, in the optical frame first.
    k = intrinsics_from_fov(width, height, fov)
    p_opt = np.array([rng.uniform(-0.6, 0.6) * k.cx / k.fx, rng.uniform(-0.6, 0.6) * k.cy / k.fy,
                      1.0])
    p_world = eye + rot @ p_opt
    vis = pybullet.createVisualShape(pybullet.GEOM_SPHERE, radius=0.04,
                                     rgbaColor=(1, 0, 0, 1), physicsClientId=client)
    body = pybullet.createMultiBody(0, -1, vis, basePosition=p_world.tolist(),
                                    physicsClientId=client)
    try:
        _, _, _, _, seg = pybullet.getCameraImage(
            width, height, view_matrix_from_optical(eye, rot),
            projection_matrix(width, height, fov, 0.01, 5.0),
            renderer=pybullet.ER_TINY_RENDERER, physicsClientId=client)
    finally:
        pybullet.removeBody(body, physicsClientId=client)
    # The segmentation mask: exact coverage, unlike colour thresholds that shading biases.
    mask = np.asarray(seg).reshape(height, width) == body
    assert mask.sum() > 20
    v_idx, u_idx = np.nonzero(mask)
    u, v = k.project(p_opt)
    # A sphere's image centroid sits within a fraction of a pixel of its centre's projection
    # (a half-pixel error in cx or cy would fail this).
    assert math.hypot(u_idx.mean() - u, v_idx.mean() - v) < 0.35


def test_image_buffer_fills_without_reallocating():
    buf = ImageBuffer(4, 2)
    rgba = np.arange(4 * 2 * 4, dtype=np.uint8).reshape(2, 4, 4)
    data = buf.fill_from_rgba(rgba)
    assert data is buf.data and len(data) == 24
    assert bytes(data) == rgba[:, :, :3].tobytes()


def test_image_buffer_writes_into_the_messages_own_array():
    from sensor_msgs.msg import Image
    msg = Image(height=2, width=4, encoding='rgb8', step=12, data=bytes(24))
    buf = ImageBuffer(4, 2, msg.data)
    rgba = np.full((2, 4, 4), 7, np.uint8)
    buf.fill_from_rgba(rgba)
    assert bytes(msg.data) == bytes([7] * 24)
    with pytest.raises(ValueError):
        ImageBuffer(4, 2, msg.data[:10])
