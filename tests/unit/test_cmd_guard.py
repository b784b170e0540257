"""Command safety: clamping, timeout and rejection of non-finite values."""
import math

import pytest

from controllers.cmd_guard import CommandGuard, non_finite_fields, rate_limited


def make():
    return CommandGuard((0.2, 0.2), timeout=0.5)


def test_within_limits_passes_unchanged():
    result = make().submit((0.1, -0.15), now=1.0)
    assert result.accepted and not result.clamped
    assert result.command == (0.1, -0.15)


@pytest.mark.parametrize('cmd, expected', [
    ((1.0, 0.0), (0.2, 0.0)),
    ((-5.0, 3.0), (-0.2, 0.2)),
    ((0.0, -0.21), (0.0, -0.2)),
])
def test_clamped_to_limits(cmd, expected):
    result = make().submit(cmd, now=0.0)
    assert result.accepted and result.clamped
    assert result.command == expected


@pytest.mark.parametrize('bad', [(math.nan, 0.0), (0.1, math.inf), (-math.inf, math.nan)])
def test_non_finite_is_rejected_and_stops(bad):
    guard = make()
    guard.submit((0.1, 0.1), now=0.0)
    result = guard.submit(bad, now=0.1)
    assert not result.accepted
    assert 'non-finite' in result.reason
    assert guard.active_command(0.1) == (0.0, 0.0)


def test_a_non_finite_value_in_any_twist_field_is_named():
    assert non_finite_fields((0.3, 0.0, 0.0, 0.0, 0.0, 0.0)) == ''
    assert non_finite_fields((0.3, 0.0, 0.0, math.nan, 0.0, 0.0)) == 'angular.x=nan'
    assert non_finite_fields((0.0, math.inf, 0.0, 0.0, -math.inf, 0.0)) == \
        'linear.y=inf, angular.y=-inf'


def test_timeout_stops_after_silence():
    guard = make()
    guard.submit((0.1, 0.0), now=10.0)
    assert guard.active_command(10.5) == (0.1, 0.0)
    assert not guard.timed_out(10.5)
    assert guard.active_command(10.5001) == (0.0, 0.0)
    assert guard.timed_out(10.5001)
    guard.submit((0.05, 0.0), now=11.0)
    assert guard.active_command(11.2) == (0.05, 0.0)


def test_nothing_received_means_zero():
    assert make().active_command(0.0) == (0.0, 0.0)


def test_bad_configuration_raises():
    with pytest.raises(ValueError):
        CommandGuard((0.2, -1.0), 0.5)
    with pytest.raises(ValueError):
        CommandGuard((0.2, 0.2), 0.0)
    with pytest.raises(ValueError):
        make().submit((0.1,), now=0.0)


def test_rate_limited_moves_each_component_by_at_most_its_step_and_lands_exactly():
    assert rate_limited((0.0, 0.0, 0.0), (0.8, -0.01, 1.0), (0.1, 0.1, 0.2)) == \
        (0.1, -0.01, 0.2)
    # Within a step of the target: exactly the target (no float residue to chase forever).
    assert rate_limited((0.1, 0.7), (0.3, 0.3), (0.25, 0.5)) == (0.3, 0.3)
