"""Rejection log lines: one per key and period, each counting the lines it stood for."""
import pytest

from ros_common.log_limit import KeyedLimiter


def test_each_key_has_its_own_period_and_the_next_line_counts_the_held_ones():
    limit = KeyedLimiter(1.0)
    assert limit.text(('youbot', 'arm'), 0.0, 'a') == 'a'
    assert limit.text(('zu12', 'arm'), 0.1, 'b') == 'b'          # another key: not held
    assert [limit.text(('youbot', 'arm'), t, 'a') for t in (0.2, 0.5, 0.9)] == [None] * 3
    assert limit.text(('youbot', 'arm'), 1.0, 'a') == 'a (and 3 more like it before)'
    assert limit.text(('youbot', 'arm'), 2.5, 'a') == 'a'


def test_a_negative_period_is_refused():
    with pytest.raises(ValueError):
        KeyedLimiter(-1.0)


def test_a_forgotten_key_starts_afresh_and_is_no_longer_kept():
    limit = KeyedLimiter(1.0)
    assert limit.text('page 1', 0.0, 'a') == 'a'
    assert limit.text('page 1', 0.5, 'a') is None
    limit.forget('page 1')
    limit.forget('page 2')                          # (never seen: nothing to drop)
    assert limit.text('page 1', 0.6, 'a') == 'a'    # (its held line went with it)
    limit.forget('page 1')
    assert not limit._state
