"""The belt's speed as the vision's tracks tell it (controllers/belt_speed.py)."""
import math
import random

import pytest

from controllers.belt_speed import MIN_SPAN_S, WINDOW_S, BeltSpeedEstimate


def _track(estimate, track, speed, t0, t1, x0=-1.0, rate=15.0, noise=0.0, rng=None):
    """Sightings of one material at ``rate`` frames a second between running times t0, t1: at
    ``x0 + speed * t``."""
    n = int(round((t1 - t0) * rate)) + 1
    for k in range(n):
        t = t0 + k / rate
        x = x0 + speed * t + (rng.gauss(0.0, noise) if noise else 0.0)
        estimate.sighted(track, t, x)


def test_before_any_track_it_is_the_set_point_and_says_so():
    estimate = BeltSpeedEstimate(0.1)
    assert estimate.update(2.0).speed == 0.1
    assert estimate.current.source == 'set point' and math.isinf(estimate.current.std)
    assert 'set point' in estimate.current.describe()


def test_noisy_tracks_give_the_speed_and_an_uncertainty_that_covers_it():
    """Pixel-sized noise (1.5 mm) on 15 frames a second, the belt 12 % off its set point: the
    speed within three of its standard errors, on 200 seeds."""
    outside = 0
    for seed in range(200):
        rng = random.Random(seed)
        estimate = BeltSpeedEstimate(0.1)
        _track(estimate, 1, 0.112, 0.0, 1.4, noise=0.0015, rng=rng)
        _track(estimate, 2, 0.112, 0.5, 1.4, x0=-0.9, noise=0.0015, rng=rng)
        got = estimate.update(2.0)
        assert got.source == 'vision' and got.tracks == 2 and 0.0 < got.std < 0.01
        outside += abs(got.speed - 0.112) > 3 * got.std
    assert outside <= 4                     # (0.3 % expected outside 3 sigma)


def test_a_track_too_short_gives_nothing_and_the_last_estimate_holds():
    estimate = BeltSpeedEstimate(0.1)
    _track(estimate, 1, 0.09, 0.0, MIN_SPAN_S * 0.5)
    assert estimate.update(2.0).source == 'set point'
    _track(estimate, 1, 0.09, MIN_SPAN_S * 0.5 + 1 / 15, 1.0)
    assert estimate.update(2.0).speed == pytest.approx(0.09)
    # The track leaves the view; later ones are too short: 0.09 holds, stamped when it was seen.
    estimate.forget(1)
    _track(estimate, 2, 0.2, 5.0, 5.0 + MIN_SPAN_S * 0.5)
    held = estimate.update(5.1)
    assert held.speed == pytest.approx(0.09) and held.stamp == pytest.approx(1.0, abs=0.05)
    assert '4.1 s old' in held.describe()


def test_only_the_last_window_counts_so_a_change_of_speed_is_followed():
    estimate = BeltSpeedEstimate(0.1)
    _track(estimate, 1, 0.10, 0.0, 3.0)
    assert estimate.update(2.0).speed == pytest.approx(0.10)
    _track(estimate, 2, 0.13, 3.0, 3.0 + WINDOW_S + 0.2, x0=-1.4)
    estimate.forget(1)
    assert estimate.update(3.0 + WINDOW_S + 0.2).speed == pytest.approx(0.13)


def test_frames_while_the_belt_stood_still_say_nothing_of_its_speed():
    """Running time stands still while the belt is stopped: a second sighting at the same
    running time replaces the first (the material did not move), no slope of zero."""
    estimate = BeltSpeedEstimate(0.1)
    _track(estimate, 1, 0.1, 0.0, 0.6)
    for _ in range(30):                 # the belt stopped at running time 0.6 for 2 s
        estimate.sighted(1, 0.6, -1.0 + 0.1 * 0.6)
    _track(estimate, 1, 0.1, 0.6 + 1 / 15, 1.2)
    assert estimate.update(2.0).speed == pytest.approx(0.1)


def test_a_nonsense_sighting_is_ignored_and_a_nonsense_setting_refused():
    estimate = BeltSpeedEstimate(0.1)
    _track(estimate, 1, 0.1, 0.0, 1.0)
    estimate.sighted(1, 1.1, math.nan)
    estimate.sighted(1, math.inf, 0.0)
    assert estimate.update(2.0).speed == pytest.approx(0.1)
    for bad in (math.nan, -0.1, math.inf):
        with pytest.raises(ValueError):
            BeltSpeedEstimate(bad)
    with pytest.raises(ValueError):
        BeltSpeedEstimate(0.1, window=0.1, min_span=0.2)
