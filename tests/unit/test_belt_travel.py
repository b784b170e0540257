"""The conveyor drive's encoder, as the simulator reads it and the cell takes it in: whole
counts of the belt's travel, its speed with the drive's noise; the cell carries a material by
the counts between two times, and weighs the encoder's speed with the tracks'."""
import math

import pytest

from controllers.belt_speed import BeltSpeedEstimate
from controllers.belt_travel import SPEED_WINDOW_S, BeltTravel
from sim_bridge.belt_encoder import BeltEncoder
from world_description.errors import WorldConfigError
from world_description.resources import resolve_resource
from world_description.world_loading import load_world
from world_description.world_schema import BeltEncoderConfig


def test_the_encoder_counts_whole_counts_and_reads_its_speed_over_each_period():
    enc = BeltEncoder(BeltEncoderConfig(resolution=1e-3), seed=1)
    assert enc.read(0.0, 0.0) == (0.0, 0.0)
    travel, speed = enc.read(0.1, 0.01234)            # 12.34 mm: 12 counts
    assert travel == pytest.approx(0.012) and speed == pytest.approx(0.12)
    travel, speed = enc.read(0.2, 0.01234)            # stood still
    assert travel == pytest.approx(0.012) and speed == 0.0


def test_the_encoder_s_noise_is_the_drive_s_and_the_same_for_the_same_seed():
    config = BeltEncoderConfig(resolution=1e-4, noise=0.002)
    runs = []
    for seed in (7, 7, 8):
        enc = BeltEncoder(config, seed)
        runs.append([enc.read(0.1 * k, 0.01 * k)[1] for k in range(1, 2001)])
    assert runs[0] == runs[1] and runs[0] != runs[2]
    errors = [s - 0.1 for s in runs[0][1:]]
    mean = sum(errors) / len(errors)
    std = math.sqrt(sum((e - mean) ** 2 for e in errors) / len(errors))
    assert abs(mean) < 0.0002 and std == pytest.approx(0.002, rel=0.1)


def test_the_travel_between_two_times_is_read_off_the_counts():
    belt = BeltTravel(1e-4)
    for k in range(31):                            # 30 Hz, a belt that speeds up
        t = k / 30.0
        belt.read(t, 0.1 * t + 0.05 * t * t)
    assert belt.travel(0.2, 0.8) == pytest.approx(0.1 * 0.6 + 0.05 * (0.64 - 0.04), abs=2e-4)
    assert belt.travel(0.5, 1.2) is None              # past the newest reading
    assert belt.travel(-0.1, 0.5) is None             # before the first
    belt.read(0.5, 99.0)                              # an old reading: ignored
    belt.read(math.nan, 1.0)
    assert belt.newest == pytest.approx(1.0) and belt.at(1.0) == pytest.approx(0.15)


def test_the_encoder_s_speed_is_over_the_running_time_of_its_window():
    belt = BeltTravel(1e-4)
    assert belt.speed(lambda a, b: b - a) is None
    for k in range(61):
        t = k / 30.0
        belt.read(t, 0.12 * t)
    speed, std = belt.speed(lambda a, b: b - a)
    assert speed == pytest.approx(0.12, abs=1e-3) and std == pytest.approx(
        math.sqrt(2) * 1e-4 / SPEED_WINDOW_S)
    # Stopped for half the window: the travel is over the time it ran.
    speed, _ = belt.speed(lambda a, b: (b - a) / 2)
    assert speed == pytest.approx(0.24, abs=2e-3)
    assert belt.speed(lambda a, b: (b - a) / 3) is None       # ran too little of it


def test_the_estimate_weighs_the_encoder_with_the_tracks_by_how_well_each_is_known():
    est = BeltSpeedEstimate(0.1)
    for k in range(20):                            # a track that says 0.11 m/s
        est.sighted(1, k / 15.0, 0.11 * k / 15.0)
    vision = est.update(20 / 15.0)
    assert vision.source == 'vision' and vision.speed == pytest.approx(0.11, abs=1e-3)
    est.measured(20 / 15.0, 0.1005, 0.0001)        # the drive's
    both = est.update(20 / 15.0)
    assert both.source == 'encoder' and both.tracks == 1
    w_vision, w_drive = 1 / vision.std ** 2, 1 / 0.0001 ** 2
    assert both.speed == pytest.approx((w_vision * vision.speed + w_drive * 0.1005)
                                       / (w_vision + w_drive))
    assert vision.speed > both.speed > 0.1005
    assert both.std == pytest.approx((w_vision + w_drive) ** -0.5)
    assert 'encoder, 1 tracks' in both.describe()
    # An encoder reading older than the window is not used.
    later = BeltSpeedEstimate(0.1)
    later.measured(0.0, 0.2, 0.0003)
    for k in range(60, 80):
        later.sighted(1, k / 15.0, 0.11 * k / 15.0)
    assert later.update(80 / 15.0).source == 'vision'


def test_carried_between_readings_at_a_wrong_speed_is_made_good_at_the_next_reading():
    """Read at 10 Hz and carried at 30 Hz with a speed 20 % high, the travel between readings
    is reckoned, and each reading makes good what that got wrong (a shortfall is held back,
    never carried backwards): the total is the counted travel at every reading."""
    belt, true_speed, always = BeltTravel(1e-4), 0.1, (lambda t0, t1: max(0.0, t1 - t0))
    total, t_prev = 0.0, 0.0
    belt.read(0.0, 0.0)
    for k in range(1, 91):                         # 3 s of decisions at 30 Hz
        t = k / 30.0
        if k % 3 == 0:                             # the drive's readings, 10 Hz
            belt.read(t, math.floor(true_speed * t / 1e-4) * 1e-4)
        step = belt.carry(t_prev, t, 1.2 * true_speed, always)
        assert step >= 0.0
        total, t_prev = total + step, t
        if k % 3 == 0:
            assert total == pytest.approx(belt.at(t), abs=1e-9)
        else:                                      # off by the reckoning since the reading
            assert abs(total - true_speed * t) <= 0.2 * true_speed * 0.1 + 2e-4


def test_a_world_gives_its_encoder_a_rate_of_its_own_and_a_bad_one_is_refused(tmp_path):
    base = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')
    for rate, ok in ((25.0, True), (None, True), (0.0, False), ('fast', False)):
        encoder = {'resolution': 1e-4} if rate is None else {'resolution': 1e-4, 'rate': rate}
        path = tmp_path / 'w.yaml'
        path.write_text(f'extends: {base}\nconveyor: {{encoder: {encoder!r}}}\n')
        if ok:
            assert load_world(path).conveyor.encoder.rate == (rate or 10.0)
        else:
            with pytest.raises(WorldConfigError, match='conveyor.encoder'):
                load_world(path)
