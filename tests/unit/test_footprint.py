"""The cell seen from above (world_description/footprint.py) under the report's paths."""
import numpy as np
import pytest

from studies.report import cell_shapes
from world_description.footprint import footprints
from world_description.resources import resolve_resource
from world_description.world_config import load_world, world_data

CELL = 'package://world_description/worlds/pipeline_cell.yaml'


def test_the_cells_landmarks_where_the_world_puts_them():
    shapes = {f.name: f for f in footprints(load_world(resolve_resource(CELL)))}
    assert {'ground_target', 'pool_floor', 'pool_platform', 'belt', 'zu12', 'youbot'} <= \
        set(shapes)
    belt = shapes['belt'].outline
    assert belt[:, 0].min() == pytest.approx(-1.0) and belt[:, 0].max() == pytest.approx(0.7)
    assert belt[:, 1].mean() == pytest.approx(0.75)
    pool = shapes['pool_floor'].outline
    assert pool.mean(axis=0) == pytest.approx((2.1, -1.3))
    assert np.ptp(pool, axis=0) == pytest.approx((0.6, 0.6))
    assert not shapes['pool_wall_n'].label and shapes['pool_floor'].label     # (thin walls)
    assert shapes['youbot'].outline.mean(axis=0) == pytest.approx((0.8, 0.05), abs=1e-9)


def test_a_maps_landmarks_come_from_the_world_file_or_a_results_copy_of_it():
    from_file = cell_shapes(CELL)
    from_copy = cell_shapes(data=world_data(resolve_resource(CELL)))
    assert [s[0] for s in from_file] == [s[0] for s in from_copy] and len(from_file) >= 8
    assert cell_shapes('no/such/world.yaml') == [] and cell_shapes() == []


def test_a_path_drawn_over_an_identical_one_leaves_it_in_sight(tmp_path):
    import cv2

    from recording.plot import COLORS, plot_paths
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    plot_paths({'first': path, 'second': path.copy()}, tmp_path / 'paths.png', 'two runs')
    img = cv2.imread(str(tmp_path / 'paths.png')).astype(int)
    below_legend = img[200:, 500:]          # (the x = 1 leg of both paths, not the legend)

    def pixels(rgb):
        return int((np.abs(below_legend - rgb[::-1]).sum(axis=2) < 40).sum())
    first, second = pixels(COLORS[0]), pixels(COLORS[1])
    # The second (2 px) runs down the middle of the first (6 px), which shows on both sides
    # (drawn alike, the second would hide the first but for its antialiased fringe).
    assert second > 1000 and first > second / 2
