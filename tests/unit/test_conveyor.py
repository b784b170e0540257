"""The accumulating belt's rule, shared by the simulator and the coordinator."""
import math

import pytest

from controllers.conveyor import Item, advance, held

SIZE = 0.05


def cube(along, across=0.0):
    return Item(along, across, SIZE, SIZE)


def test_free_items_move_as_far_as_the_belt():
    assert advance([cube(0.1), cube(0.5)], math.inf, 0.2) == pytest.approx([0.3, 0.7])
    assert held([cube(0.1), cube(0.5)], math.inf) == [False, False]


def test_the_stop_holds_the_first_and_the_first_holds_the_next():
    stop = 1.0
    # 0.2 m of travel: the front one reaches the stop, the next one its back face.
    out = advance([cube(0.92), cube(0.85)], stop, 0.2)
    assert out == pytest.approx([stop - SIZE / 2, stop - 1.5 * SIZE])
    assert held([cube(x) for x in out], stop) == [True, True]


def test_an_item_beside_the_queue_passes_it():
    stop = 1.0
    out = advance([cube(0.975), cube(0.8, across=0.06)], stop, 0.5)
    # Across, they do not overlap: the second one goes on to the stop itself.
    assert out == pytest.approx([0.975, 0.975])


def test_taking_the_front_item_releases_the_ones_it_held():
    stop = 1.0
    queue = [cube(0.975), cube(0.925), cube(0.875)]
    assert held(queue, stop) == [True, True, True]
    rest = queue[1:]
    assert held(rest, stop) == [False, False]
    assert advance(rest, stop, 0.01) == pytest.approx([0.935, 0.885])
    assert advance(rest, stop, 1.0) == pytest.approx([0.975, 0.925])


def test_the_result_does_not_depend_on_the_order_given():
    items = [cube(0.3), cube(0.95), cube(0.6), cube(0.9)]
    out = advance(items, 1.0, 0.4)
    reordered = advance(items[::-1], 1.0, 0.4)[::-1]
    assert out == pytest.approx(reordered)
    assert sorted(out) == pytest.approx([0.7, 0.875, 0.925, 0.975])


def test_bad_travel_is_refused():
    with pytest.raises(ValueError):
        advance([cube(0.1)], 1.0, -0.1)
    with pytest.raises(ValueError):
        advance([cube(0.1)], 1.0, math.nan)
