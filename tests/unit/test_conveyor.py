"""The accumulating belt's rule, shared by the simulator and the coordinator."""
import math

import pytest

from controllers.conveyor import QUEUE_GAP_M, Item, advance, held

SIZE = 0.05


def cube(along, across=0.0):
    return Item(along, across, SIZE, SIZE)


def test_free_items_move_as_far_as_the_belt():
    assert advance([cube(0.1), cube(0.5)], math.inf, 0.2) == pytest.approx([0.3, 0.7])
    assert held([cube(0.1), cube(0.5)], math.inf) == [False, False]


def test_the_stop_holds_the_first_and_the_first_holds_the_next():
    stop = 1.0
    # 0.2 m of travel: the front one reaches the stop, the next one comes to a gap short of its
    # back face (zero-pressure accumulation: queued items never press on each other).
    out = advance([cube(0.92), cube(0.85)], stop, 0.2)
    assert out == pytest.approx([stop - SIZE / 2, stop - 1.5 * SIZE - QUEUE_GAP_M])
    assert held([cube(x) for x in out], stop) == [True, True]


def test_an_item_beside_the_queue_passes_it():
    stop = 1.0
    out = advance([cube(0.975), cube(0.8, across=0.06)], stop, 0.5)
    # Across, they do not overlap: the second one goes on to the stop itself.
    assert out == pytest.approx([0.975, 0.975])


def test_taking_the_front_item_releases_the_ones_it_held():
    stop = 1.0
    g = QUEUE_GAP_M
    queue = [cube(0.975), cube(0.925 - g), cube(0.875 - 2 * g)]
    assert held(queue, stop) == [True, True, True]
    rest = queue[1:]
    assert held(rest, stop) == [False, False]
    assert advance(rest, stop, 0.01) == pytest.approx([0.935 - g, 0.885 - 2 * g])
    assert advance(rest, stop, 1.0) == pytest.approx([0.975, 0.925 - g])


def test_the_result_does_not_depend_on_the_order_given():
    items = [cube(0.3), cube(0.95), cube(0.6), cube(0.9)]
    out = advance(items, 1.0, 0.4)
    reordered = advance(items[::-1], 1.0, 0.4)[::-1]
    assert out == pytest.approx(reordered)
    g = QUEUE_GAP_M
    assert sorted(out) == pytest.approx([0.7, 0.875 - 2 * g, 0.925 - g, 0.975])


def test_an_item_being_lifted_off_holds_the_ones_behind_until_it_is_clear():
    """The front item, lifted by a gripper, is off the belt but still in the lane: the next
    one waits behind it (driven into its back face, it would be pushed aside); once it is
    clear (no longer given), the queue moves up."""
    stop = 1.0
    lifted = cube(0.975)
    queue = [cube(0.925 - QUEUE_GAP_M), cube(0.875 - 2 * QUEUE_GAP_M)]
    assert held(queue, stop, obstacles=[lifted]) == [True, True]
    assert advance(queue, stop, 0.5, obstacles=[lifted]) == pytest.approx(
        [q.along for q in queue])
    assert held(queue, stop) == [False, False]
    assert advance(queue, stop, 0.5) == pytest.approx([0.975, 0.925 - QUEUE_GAP_M])
    # An obstacle beside the lane blocks nothing.
    assert advance(queue[:1], stop, 0.5, obstacles=[cube(0.975, across=0.06)]) == \
        pytest.approx([0.975])


def test_bad_travel_is_refused():
    with pytest.raises(ValueError):
        advance([cube(0.1)], 1.0, -0.1)
    with pytest.raises(ValueError):
        advance([cube(0.1)], 1.0, math.nan)
