"""Bezier paths through key poses, the dummy's motion profile and the PD follower."""
import math

import numpy as np
import pytest

from controllers.bezier import BezierPath, MotionProfile, PathError, key_poses_between
from controllers.path_follower import PathFollower, PDGains, TurnLimits, simulate_kinematic

KEYS = [(0.6, -0.55, 0.0), (1.2, -1.0, 0.3), (1.72, -1.75, 0.0), (1.78, -2.15, -0.5)]


def test_the_path_passes_through_every_key_pose():
    path = BezierPath(KEYS)
    dense = path.sample(0.001)
    for key in KEYS[1:-1]:
        d = np.hypot(dense[:, 0] - key[0], dense[:, 1] - key[1])
        assert d.min() < 2e-3
    assert path.pose(0.0) == pytest.approx(KEYS[0], abs=1e-9)
    assert path.pose(path.length) == pytest.approx(KEYS[-1], abs=1e-9)


def test_arc_length_is_at_least_the_chord_and_close_for_a_straight_line():
    straight = BezierPath([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0)])
    assert straight.length == pytest.approx(2.0, abs=1e-9)
    assert straight.pose(0.7)[:2] == pytest.approx((0.7, 0.0), abs=1e-6)
    curved = BezierPath(KEYS)
    chords = sum(math.dist(a[:2], b[:2]) for a, b in zip(KEYS, KEYS[1:]))
    assert chords <= curved.length < 1.2 * chords


def test_the_tangent_is_continuous_at_the_key_points():
    path = BezierPath(KEYS)
    s = np.linspace(0.0, path.length, 4001)
    tangents = np.array([path.tangent(v) for v in s])
    turn = np.arccos(np.clip(np.sum(tangents[1:] * tangents[:-1], axis=1), -1, 1))
    assert turn.max() < 0.02          # no corner anywhere (rad per 0.6 mm)


def test_headings_blend_the_short_way_round():
    path = BezierPath([(0.0, 0.0, math.radians(170)), (1.0, 0.0, math.radians(-170))])
    mid = path.pose(path.length / 2)[2]
    assert abs(abs(mid) - math.pi) < 1e-6


@pytest.mark.parametrize('keys', [[(0, 0, 0)], [(0, 0, 0), (0, 0, 1)],
                                  [(0, 0, 0), (1, float('nan'), 0)], [(0, 0), (1, 1)]])
def test_bad_key_poses_are_refused(keys):
    with pytest.raises(PathError):
        BezierPath(keys)


def test_the_profile_respects_speed_and_acceleration():
    p = MotionProfile(2.0, 0.4, 0.4)
    t = np.linspace(0.0, p.duration, 2001)
    s, v = np.array([p.at(x) for x in t]).T
    assert s[0] == 0.0 and s[-1] == pytest.approx(2.0)
    assert v.max() <= 0.4 + 1e-12
    assert np.all(np.diff(s) >= -1e-12)
    accel = np.abs(np.diff(v) / np.diff(t))
    assert accel.max() <= 0.4 + 1e-6
    assert p.duration == pytest.approx(2.0 / 0.4 + 0.4 / 0.4)
    short = MotionProfile(0.1, 0.4, 0.4)       # triangular: never reaches 0.4 m/s
    assert max(short.at(x)[1] for x in np.linspace(0, short.duration, 500)) < 0.4


def test_a_profile_stretched_to_a_duration_takes_exactly_that_long():
    fastest = MotionProfile(0.7, 0.6, 0.6)
    for duration in (fastest.duration + 0.01, 3.0, 10.0):
        p = MotionProfile.lasting(0.7, duration, 0.6, 0.6)
        assert p.duration == pytest.approx(duration, abs=1e-9)
        assert p.at(duration)[0] == pytest.approx(0.7)
        assert p.max_speed < 0.6
    # Asked for less than the fastest: the fastest (the limits always hold).
    assert MotionProfile.lasting(0.7, 0.5, 0.6, 0.6).duration == fastest.duration
    # A length next to nothing (a turn of 1e-17 rad, between two drives of a fleet) stretched
    # over seconds: a profile, not an error (its speed came out 0 to rounding).
    for tiny in (1e-17, 1e-300):
        p = MotionProfile.lasting(tiny, 4.0, 1.5, 2.0)
        assert p.max_speed > 0.0 and p.duration == pytest.approx(4.0, abs=1e-6)
    assert MotionProfile.lasting(5e-324, 4.0, 1.5, 2.0).max_speed == 1.5


def test_a_holonomic_turn_runs_on_its_own_profile_and_ends_with_the_travel():
    """Half a turn over 0.7 m (between the youBot's stands): the heading profile sets the
    time, the travel is stretched to it; both start and end together, the turn within its
    rate and acceleration, the way round the key poses go (through yaw 0 here, clockwise)."""
    keys = [(0.0, 0.0, -math.pi / 2), (-0.3, 0.2, 0.0), (0.0, 0.35, math.pi / 2)]
    limits = TurnLimits(rate=1.2, accel=1.5)
    follower = PathFollower(BezierPath(keys), 0.0, max_speed=0.6, max_accel=0.6, turn=limits,
                            gains=PDGains(max_speed=0.75, max_turn=1.4))
    spin = MotionProfile(math.pi, 1.2, 1.5)
    assert follower.profile.duration == pytest.approx(spin.duration)
    t = np.linspace(0.0, follower.end_time, 3001)
    dummies = [follower.dummy(x) for x in t]
    yaw = np.unwrap([d[0][2] for d in dummies])
    assert yaw[0] == pytest.approx(-math.pi / 2) and yaw[-1] == pytest.approx(math.pi / 2)
    assert np.all(np.diff(yaw) >= -1e-12)                # counter-clockwise throughout
    rate = np.array([d[2] for d in dummies])
    assert rate.max() <= 1.2 + 1e-9 and np.abs(np.diff(rate) / np.diff(t)).max() <= 1.5 + 1e-6
    assert np.diff(yaw) / np.diff(t) == pytest.approx(0.5 * (rate[1:] + rate[:-1]), abs=1e-2)
    speed = np.array([np.linalg.norm(d[1]) for d in dummies])
    assert speed[0] == 0.0 and speed[-1] == 0.0 and speed.max() < 0.6
    poses, statuses = simulate_kinematic(follower, keys[0])
    assert statuses[-1].finished
    assert max(s.yaw_error for s in statuses) < 0.05
    # Without it, the heading follows the path's key poses: through yaw 0 at the via point.
    plain = PathFollower(BezierPath(keys), 0.0, max_speed=0.6, max_accel=0.6)
    via = min(np.linspace(0.0, plain.end_time, 2001),
              key=lambda x: np.hypot(plain.dummy(x)[0][0] + 0.3, plain.dummy(x)[0][1] - 0.2))
    assert plain.dummy(via)[0][2] == pytest.approx(0.0, abs=1e-3)


def test_the_follower_tracks_the_dummy_and_settles_on_the_goal():
    path = BezierPath(KEYS)
    follower = PathFollower(path, 0.0, max_speed=0.4, max_accel=0.4)
    poses, statuses = simulate_kinematic(follower, KEYS[0])
    assert statuses[-1].finished
    assert np.hypot(*(poses[-1][:2] - KEYS[-1][:2])) <= 0.01
    assert max(s.position_error for s in statuses) < 0.03
    assert statuses[-1].yaw_error <= 0.02


def test_the_follower_converges_from_an_offset_start():
    path = BezierPath(KEYS)
    follower = PathFollower(path, 0.0)
    poses, statuses = simulate_kinematic(follower, (0.45, -0.35, 0.4))
    errors = [s.position_error for s in statuses]
    assert errors[0] > 0.2
    assert statuses[-1].finished
    # The error falls below 2 cm within 3 s and stays there.
    after = int(3.0 / 0.02)
    assert max(errors[after:]) < 0.02


def test_the_derivative_term_damps_the_approach():
    path = BezierPath([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)])
    overshoot = {}
    for kd in (0.0, 0.6):
        follower = PathFollower(path, 0.0, gains=PDGains(kp_xy=4.0, kd_xy=kd))
        poses, _ = simulate_kinematic(follower, (0.0, 0.2, 0.0), lag=0.25)
        overshoot[kd] = -poses[:, 1].min()     # crossing the line y = 0
    assert overshoot[0.6] < overshoot[0.0]


def test_commands_respect_the_limits():
    path = BezierPath([(0.0, 0.0, 0.0), (3.0, 0.0, 0.0)])
    follower = PathFollower(path, 0.0, max_speed=0.8, gains=PDGains(max_speed=0.3,
                                                                    max_turn=0.5))
    _, statuses = simulate_kinematic(follower, (0.0, 0.5, 1.0))
    cmds = np.array([s.command for s in statuses])
    assert np.abs(cmds[:, :2]).max() <= 0.3 + 1e-9 and np.abs(cmds[:, 2]).max() <= 0.5 + 1e-9


def test_key_poses_between_keeps_the_start_heading_for_via_points():
    keys = key_poses_between((0, 0, 0.5), (2, 0, 0.0), [(1, 1)])
    assert keys == [(0, 0, 0.5), (1, 1, 0.5), (2, 0, 0.0)]


def _stand_to_stand():
    """The youBot's turn between its two unload stands beside the pool, as the cell plans it:
    where it starts, its follower (a new one each call), and the pool's west wall's face (x)."""
    from cell_layout.world_layout import layout_from_world
    from coordinator.pipeline import Settings
    from world_description.resources import resolve_resource
    from world_description.world_config import load_world
    world = load_world(resolve_resource('package://world_description/worlds/pipeline_cell.yaml'))
    lay = layout_from_world(world)
    wall = next(o for o in world.obstacles if o.name == 'pool_wall_w')
    s, a, b = Settings(), lay.stand('pool_left').pose, lay.stand('pool_right').pose
    return a, lambda: PathFollower(
        BezierPath(key_poses_between(a, b, lay.via_turn)), 0.0, s.drive_speed, s.drive_accel,
        PDGains(max_speed=s.base_max_speed, max_turn=s.base_max_turn),
        turn=TurnLimits(s.drive_turn, s.drive_turn_accel)), wall.position[0] - wall.size[0] / 2


def _east(poses):
    """The easternmost point of the youBot's outline: its 0.57 m x 0.36 m box, and its wheels,
    which stand out to 0.209 m from its centre line, 0.228 m before and behind its centre."""
    return max(x + abs(math.cos(th)) * a + abs(math.sin(th)) * b
               for x, _, th in poses for a, b in ((0.285, 0.18), (0.228, 0.209)))


def test_the_lead_keeps_a_turning_base_on_its_path_when_commands_arrive_late():
    """Commands that take effect 0.2 s after the odometry they answer (a real-time run on a
    loaded machine): computed for the heading of 0.2 s ago while the base turns at 1.3 rad/s,
    they carry it 10 cm off its path, and its wheels into the pool's west wall. Predicted that
    far ahead, it stays within 2.5 cm of the dummy and 2 cm off the wall."""
    start, follower, wall = _stand_to_stand()
    poses, statuses = simulate_kinematic(follower(), start, dt=0.01, delay=0.2)
    assert max(s.position_error for s in statuses) > 0.08 and _east(poses) > wall
    poses, statuses = simulate_kinematic(follower(), start, dt=0.01, delay=0.2, lead=0.2)
    assert statuses[-1].finished
    assert max(s.position_error for s in statuses) < 0.025 and _east(poses) < wall - 0.02
    # Without a delay, no lead is needed.
    base, _ = simulate_kinematic(follower(), start, dt=0.01)
    assert _east(base) < wall - 0.02


def test_the_drive_lead_is_the_trip_and_the_age_beyond_the_clock():
    from controllers.path_follower import DriveLead
    lead = DriveLead(trip=0.1, max_lead=0.3)
    assert lead.lead(0.0) == pytest.approx(0.1)
    assert lead.lead(0.05) == pytest.approx(0.15)
    assert lead.lead(-0.5) == pytest.approx(0.1)           # a clock behind the stamp
    assert lead.lead(float('nan')) == pytest.approx(0.1)
    assert lead.lead(5.0) == 0.3
    assert lead.summary() == {'samples': 5, 'median': 0.0, 'p99': pytest.approx(4.8, abs=0.01),
                              'max': 5.0}


def test_a_fixed_lead_is_safe_over_the_range_of_delays():
    """The coordinator's 0.1 s, whatever the real delay (0 to 0.2 s): the base's outline stays
    off the pool's wall (4 mm at 0.2 s), and it settles on its stand."""
    start, follower, wall = _stand_to_stand()
    for delay in (0.0, 0.05, 0.1, 0.15, 0.2):
        poses, statuses = simulate_kinematic(follower(), start, dt=0.01, delay=delay, lead=0.1)
        assert statuses[-1].finished and _east(poses) < wall, delay
