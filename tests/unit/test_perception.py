"""Vision core: segmentation on synthetic images with known answers, pixel-to-plane
projection, the cube silhouette model, tracking, and accuracy on simulator frames."""
import math

import numpy as np
import pytest

from perception.projection import (
    CameraModel,
    cube_silhouette_centroid,
    locate_cube,
    pixel_to_plane,
)
from perception.segmentation import ColorClass, classes_of, confidence
from perception.segmentation import segment as segment_with
from perception.tracker import Sighting, Tracker
from sim_bringup.vision_evaluation import evaluate
from world_description import PIPELINE_CELL
from world_description.camera_geometry import look_at_rotation
from world_description.resources import resolve_resource
from world_description.world_config import load_world

# The paper cell's classes, as its world file gives them.
CLASSES = classes_of(load_world(resolve_resource(PIPELINE_CELL)).materials)


def segment(rgb, **kwargs):
    return segment_with(rgb, CLASSES, **kwargs)

K = np.array([[290.0, 0.0, 160.0], [0.0, 290.0, 119.0], [0.0, 0.0, 1.0]])
CAMERA = CameraModel(K, look_at_rotation((-0.55, 0.75, 1.25), (-0.55, 0.75, 0.4)),
                     np.array([-0.55, 0.75, 1.25]))
RGB = {'purple': (128, 38, 178), 'orange': (255, 128, 13), 'blue': (26, 77, 230)}


def _image(squares, background=(38, 38, 43)):
    img = np.zeros((240, 320, 3), np.uint8)
    img[:] = background
    for color, (x, y, w, h) in squares:
        img[y:y + h, x:x + w] = RGB[color]
    return img


def test_segmentation_finds_each_square_with_its_colour_and_centroid():
    squares = [('purple', (20, 30, 12, 12)), ('orange', (100, 100, 15, 15)),
               ('blue', (250, 200, 10, 10)), ('orange', (200, 40, 12, 12))]
    blobs = segment(_image(squares))
    found = sorted((b.color, round(b.u, 3), round(b.v, 3), b.area) for b in blobs)
    expected = sorted((c, x + (w - 1) / 2, y + (h - 1) / 2, float(w * h))
                      for c, (x, y, w, h) in squares)
    assert found == expected
    assert all(b.purity == 1.0 for b in blobs)


def test_grey_floor_belt_and_small_specks_are_not_materials():
    img = _image([('orange', (100, 100, 2, 2))])
    img[:, :50] = (209, 204, 194)                              # the floor's grey
    assert segment(img, min_area=20.0) == []


def test_segmentation_survives_lighting_and_colour_noise():
    rng = np.random.default_rng(3)
    squares = [('purple', (40, 40, 14, 14)), ('orange', (150, 120, 14, 14)),
               ('blue', (260, 60, 14, 14))]
    for _ in range(50):
        img = _image(squares).astype(float)
        img = img * rng.uniform(0.85, 1.15, 3) * rng.uniform(0.6, 1.3)
        img += rng.normal(0.0, 6.0, img.shape)
        blobs = segment(np.clip(img, 0, 255).astype(np.uint8), min_area=40.0)
        assert sorted(b.color for b in blobs) == ['blue', 'orange', 'purple']


def test_colour_classes_validate_and_wrap():
    red = ColorClass('red', ((170, 5),))
    hsv = np.array([[[175, 200, 200], [3, 200, 200], [90, 200, 200]]], np.uint8)
    assert red.mask(hsv).tolist() == [[1, 1, 0]]
    with pytest.raises(ValueError):
        ColorClass('x', ())
    with pytest.raises(ValueError):
        ColorClass('x', ((0, 200),))
    with pytest.raises(ValueError):
        segment(np.zeros((10, 10), np.uint8))


def test_pixel_to_plane_inverts_projection():
    rng = np.random.default_rng(0)
    for _ in range(100):
        p = np.array([rng.uniform(-0.9, -0.2), rng.uniform(0.4, 1.1), 0.45])
        u, v = CAMERA.project(p[None])[0]
        assert pixel_to_plane(CAMERA, u, v, 0.45) == pytest.approx(p, abs=1e-9)
    # The principal point looks straight down.
    assert pixel_to_plane(CAMERA, 160.0, 119.0, 0.4) == pytest.approx((-0.55, 0.75, 0.4))


def test_the_silhouette_model_recovers_a_cube_off_the_optical_axis():
    centre = np.array([-0.25, 1.05, 0.425])          # far from the axis: sides show
    u, v = cube_silhouette_centroid(CAMERA, centre, 0.05, 0.0)
    naive = pixel_to_plane(CAMERA, u, v, 0.425)
    located, residual = locate_cube(CAMERA, u, v, 0.4, 0.05)
    assert np.linalg.norm(naive[:2] - centre[:2]) > 0.001       # the bias it removes
    assert located == pytest.approx(centre, abs=1e-6) and residual < 1e-3


def test_confidence_falls_with_implausible_size():
    blob = segment(_image([('orange', (100, 100, 12, 12))]))[0]
    assert confidence(blob, 144.0) == pytest.approx(1.0)
    assert confidence(blob, 576.0) == pytest.approx(0.25)
    assert confidence(blob, 36.0) == pytest.approx(0.25)


def _obs(x, color='orange'):
    return Sighting(color, np.array([x, 0.75, 0.425]), 0.0, 0.0, 1.0)


def test_tracker_keeps_one_id_per_material_and_never_reuses_ids():
    tracker = Tracker(gate=0.04, min_hits=3, max_missed=2)
    seen = []
    for k in range(20):                           # two materials moving at 0.1 m/s, 15 Hz
        t = k / 15
        obs = [_obs(-0.9 + 0.1 * t), _obs(-0.6 + 0.1 * t, 'blue')]
        seen.append({tr.id: tr.color for tr in tracker.update(t, obs)})
    assert seen[0] == {} and seen[2] == {1: 'orange', 2: 'blue'}
    assert all(s == {1: 'orange', 2: 'blue'} for s in seen[2:])
    track = next(tr for tr in tracker.tracks if tr.id == 1)
    assert track.velocity() == pytest.approx((0.1, 0.0, 0.0), abs=1e-9)
    for k in range(20, 24):                       # both leave the view
        tracker.update(k / 15, [])
    assert tracker.tracks == []
    tracker.update(2.0, [_obs(-0.9)])
    assert tracker.tracks[0].id == 3
    assert tracker.confirmed_ids == [1, 2]


def test_a_colour_outvoted_flickers_into_lower_confidence():
    tracker = Tracker(min_hits=1)
    for k, color in enumerate(['orange', 'orange', 'purple', 'orange']):
        tracks = tracker.update(k / 15, [_obs(0.0, color)])
    assert tracks[0].color == 'orange' and tracks[0].confidence == pytest.approx(0.75)


@pytest.mark.slow
def test_accuracy_on_simulator_frames_with_noise():
    acc = evaluate(runs=2, frames_per_run=90, seed=11, noise=1.0)
    assert acc.visible > 100
    assert acc.identification_rate >= 0.999
    assert acc.false_colours == 0 and acc.spurious == 0
    assert max(acc.errors_m) < 0.005
    # Each track is one material, and each material one track.
    assert all(len(materials) == 1 for materials in acc.tracks.values())
    per_material = {}
    for (run, _), materials in acc.tracks.items():
        key = (run, next(iter(materials)))
        per_material[key] = per_material.get(key, 0) + 1
    assert set(per_material.values()) == {1}
    assert math.isfinite(np.median(acc.latencies_s))


def test_camera_info_that_cannot_be_used_is_named():
    """Issue 15, finding 7: a camera_info with NaN in K was taken, and the vision node went
    blind until a valid one came."""
    from perception.projection import intrinsics_problem
    good = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
    assert intrinsics_problem(640, 480, good) == ''
    for width, height, k, why in [
            (640, 480, [float('nan')] + good[1:], 'not finite'),
            (640, 480, good[:2] + [float('inf')] + good[3:], 'not finite'),
            (0, 480, good, 'size'),
            (640, 480, [-500.0] + good[1:], 'focal lengths'),
            (640, 480, good[:2] + [700.0] + good[3:], 'principal point'),
            (640, 480, good[:8] + [0.0], 'last row'),
            (640, 480, good[:5], '5 values')]:
        assert why in intrinsics_problem(width, height, k), (k, why)
