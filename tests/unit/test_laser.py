"""The laser scanner on a mobile base: the simulator's scans (sim_bridge.laser), the world's
``laser`` entry, and a base's pose from its odometry and its scans matched to the world's
walls (controllers.scan_localizer, cell_layout.scan_map)."""
import math

import numpy as np
import pytest
import yaml

from cell_layout.scan_map import walls_at
from controllers.scan_localizer import (
    Scan,
    ScanLocalizer,
    WallBox,
    WallMap,
    compose,
    inverse,
    match_scan,
)
from sim_bridge.frames import WorldFrames
from sim_bridge.laser import LaserScanner
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import SimWorld
from world_description.errors import WorldConfigError
from world_description.resources import resolve_resource
from world_description.world_config import parse_world

MINI = resolve_resource('package://world_description/worlds/mini_robot.yaml')
LASER = {'x': 0.06, 'z': 0.02, 'fov': 2 * math.pi - 0.01, 'rays': 1080, 'range_max': 3.0,
         'noise': 0.005}


def _mini_world(tmp_path, laser=LASER, pose=None):
    data = yaml.safe_load(MINI.read_text())
    data['robots'][0]['urdf'] = str(resolve_resource(data['robots'][0]['urdf']))
    data['robots'][0]['laser'] = laser
    if pose is not None:
        data['robots'][0]['pose'].update(pose)
    return parse_world(data, str(tmp_path / 'w.yaml'))


@pytest.fixture
def mini(tmp_path):
    w = SimWorld(_mini_world(tmp_path))
    yield w
    w.close()


def test_the_scanner_sees_the_worlds_obstacles_where_they_are(mini):
    robot = mini.robots['mini_robot']
    scanner = LaserScanner(mini.client, robot.config.laser, 'mini_robot', seed=3)
    ranges = scanner.scan(robot.base_link_world(), 10_000_000)
    assert len(ranges) == 1080
    # The red box's west face is at x = 0.85, seen from the scanner at x = 0.06 at about
    # 32 degrees left; nothing stands 60 degrees right of it within 3 m.
    towards_box = np.argmin(np.abs(scanner.angles - math.atan2(0.5, 0.82)))
    assert 0.79 / math.cos(scanner.angles[towards_box]) == pytest.approx(
        ranges[towards_box], abs=0.03)
    assert np.isinf(ranges[np.argmin(np.abs(scanner.angles + math.pi / 3))])
    hit = np.isfinite(ranges)
    assert hit.sum() > 20
    assert np.all((ranges[hit] >= 0.02) & (ranges[hit] <= 3.0))
    # The noise: the same at the same time, whoever asks; another at another time.
    again = LaserScanner(mini.client, robot.config.laser, 'mini_robot', seed=3)
    assert np.array_equal(again.scan(robot.base_link_world(), 10_000_000), ranges)
    later = scanner.scan(robot.base_link_world(), 20_000_000)
    assert not np.array_equal(later[hit], ranges[hit])
    assert np.abs(later[hit] - ranges[hit]).max() < 0.05


def test_scans_are_due_on_their_own_grid_and_the_laser_has_a_frame(mini):
    class Scans(NullSink):
        def __init__(self):
            self.due = []

        def on_scan(self, robot, t):
            self.due.append((robot, t))

    sink = Scans()
    runner = SimRunner(mini, DriveLimits(), state_rate=30.0)
    runner.advance(round(1.0 / mini.time_step), sink)
    # 10 Hz by default: at the first step, then every 0.1 s up to 1 s.
    assert [r for r, _ in sink.due] == ['mini_robot'] * 11
    assert np.allclose(np.diff([t for _, t in sink.due]), 1e8, atol=mini.time_step * 1e9)
    mount = [t for t in WorldFrames(mini).static() if t.child == 'laser']
    assert mount and mount[0].parent == 'base_link'
    assert mount[0].translation == pytest.approx((0.06, 0.0, 0.02))


@pytest.mark.parametrize('laser, why', [
    ({'range_min': 2.0, 'range_max': 1.0}, 'range_min'),
    ({'rays': 1}, 'rays'),
    ({'rate': float('nan')}, 'rate'),
    ({'height': 0.1}, 'unknown keys'),
])
def test_a_bad_laser_entry_is_refused_in_one_line(tmp_path, laser, why):
    with pytest.raises(WorldConfigError, match=why) as err:
        _mini_world(tmp_path, laser)
    assert '\n' not in str(err.value)


def test_a_laser_is_for_a_mobile_base(tmp_path):
    data = {'robots': [{'name': 'arm', 'fixed_base': True, 'laser': {},
                        'urdf': str(resolve_resource(
                            'package://robot_description/urdf/mini_robot.urdf'))}]}
    with pytest.raises(WorldConfigError, match='mobile base'):
        parse_world(data, str(tmp_path / 'w.yaml'))


def test_a_real_scan_puts_the_base_where_it_is_from_a_wrong_guess(tmp_path):
    """The simulator's scan, matched to the world's own obstacles, from a guess 6 cm and 3
    degrees off: the base's true pose within a few millimetres."""
    truth = (0.2, -0.1, 0.5)
    w = SimWorld(_mini_world(tmp_path, pose={'x': truth[0], 'y': truth[1], 'yaw': truth[2]}))
    try:
        laser = w.robots['mini_robot'].config.laser
        scanner = LaserScanner(w.client, laser, 'mini_robot', seed=1)
        ranges = scanner.scan(w.robots['mini_robot'].base_link_world(), 0)
        walls = walls_at(list(w.config.obstacles), 0.0305 + laser.z)
        loc = ScanLocalizer(walls, (laser.x, laser.y, laser.yaw), (0.08, 0.08))
        points = loc.points(Scan(0, float(scanner.angles[0]), scanner.angle_increment,
                                 laser.range_min, laser.range_max, ranges))
        found = match_scan(walls, points, np.array([laser.x, laser.y]),
                           (truth[0] + 0.05, truth[1] - 0.035, truth[2] + 0.05), LOOSE)
    finally:
        w.close()
    # (One scan counts as EFFECTIVE_POINTS points of 1 cm: a few millimetres.)
    assert found is not None and np.all(np.sqrt(np.diag(found.covariance)) < 0.006)
    assert found.pose[:2] == pytest.approx(truth[:2], abs=0.005)
    assert found.pose[2] == pytest.approx(truth[2], abs=0.005)


# --- the localizer on scans cast here against a map ---------------------------------------
POOL = [WallBox((2.1, -0.99), (0.32, 0.01)), WallBox((2.1, -1.61), (0.32, 0.01)),
        WallBox((2.41, -1.3), (0.01, 0.3)), WallBox((1.79, -1.3), (0.01, 0.3)),
        WallBox((2.1, -1.85), (0.2, 0.15))]
MOUNT = (0.31, 0.0, 0.0)
# A guess known to within 0.3 m and 0.3 rad: what the scan fixes comes from the scan.
LOOSE = np.diag([0.09, 0.09, 0.09])
FOV, RAYS = 4.18879, 241


def _cast(walls: WallMap, pose, extra=(), noise=0.005, seed=0, boxes=POOL):
    """The ranges a scanner at MOUNT on a base at ``pose`` reads of ``walls`` (the map of
    ``boxes``), and of the ``extra`` boxes, which are not in the map."""
    seen = WallMap(list(boxes) + list(extra)) if extra else walls
    origin = np.array(compose(pose, MOUNT)[:2])
    out = []
    for a in pose[2] + MOUNT[2] + np.linspace(-FOV / 2, FOV / 2, RAYS):
        d, best = np.array([math.cos(a), math.sin(a)]), math.inf
        for p, q in zip(seen.a, seen.b):
            m = np.array([d, p - q]).T
            if abs(np.linalg.det(m)) > 1e-12:
                t, u = np.linalg.solve(m, p - origin)
                if t > 0.02 and 0.0 <= u <= 1.0:
                    best = min(best, t)
        out.append(best if best < 4.0 else math.inf)
    r = np.array(out)
    return r + noise * np.random.default_rng(seed).standard_normal(RAYS)


def _scan(stamp, ranges):
    return Scan(stamp, -FOV / 2, FOV / (RAYS - 1), 0.02, 4.0, ranges)


@pytest.mark.parametrize('truth', [(1.5, -1.3, 0.0), (1.4, -2.0, 0.5), (1.2, -0.6, -0.9)])
def test_a_corner_in_view_fixes_the_whole_pose(truth):
    walls = WallMap(POOL)
    loc = ScanLocalizer(walls, MOUNT, (0.32, 0.24))
    found = match_scan(walls, loc.points(_scan(0, _cast(walls, truth))), np.array(MOUNT[:2]),
                       (truth[0] + 0.08, truth[1] - 0.05, truth[2] + 0.03), LOOSE)
    assert found is not None and found.rms < 0.01
    assert np.all(np.sqrt(np.diag(found.covariance)) < 0.015)          # (from 0.3)
    assert np.subtract(found.pose, truth) == pytest.approx((0, 0, 0), abs=0.004)


def test_one_wall_fixes_the_distance_to_it_not_the_place_along_it():
    # A wall y = 0.99 longer than the scanner's range: its ends are not in view.
    walls = WallMap([WallBox((0.0, 1.0), (10.0, 0.01))])
    truth = (0.0, 0.0, math.pi / 2)                                # facing it
    loc = ScanLocalizer(walls, MOUNT, (0.32, 0.24))
    r = _cast(walls, truth)
    prior = (0.07, -0.04, truth[2] + 0.02)
    found = match_scan(walls, loc.points(_scan(0, r)), np.array(MOUNT[:2]), prior, LOOSE)
    assert found is not None
    assert found.pose[1] == pytest.approx(0.0, abs=0.004)           # the distance
    assert found.pose[2] == pytest.approx(truth[2], abs=0.004)      # the heading
    assert found.pose[0] == pytest.approx(0.07, abs=0.01)           # along it: as guessed
    # ... and as uncertain as before along it, certain across it.
    sx, sy, syaw = np.sqrt(np.diag(found.covariance))
    assert sx == pytest.approx(0.3, rel=0.05) and sy < 0.004 and syaw < 0.004


def test_a_face_seen_to_its_end_fixes_the_place_along_it():
    """Beside a single box, its near face seen to both its corners (the rays past them find
    nothing): where along the face the base stands comes from where the face ends in the
    scan, to within a few millimetres, where the face alone leaves it as guessed."""
    box = [WallBox((1.0, 0.0), (0.2, 0.1))]                     # the face x = 0.8, |y| <= 0.1
    walls = WallMap(box)
    truth = (0.2, 0.03, 0.0)
    loc = ScanLocalizer(walls, MOUNT, (0.32, 0.24))
    points = loc.points(_scan(0, _cast(walls, truth, noise=0.003)))
    assert points.far_before.any() and points.far_after.any()
    found = match_scan(walls, points, np.array(MOUNT[:2]), (0.22, 0.08, 0.01), LOOSE)
    assert found is not None
    assert np.subtract(found.pose, truth) == pytest.approx((0, 0, 0), abs=0.006)
    # (From 0.3; the one short face leaves the heading loose, and along it with it.)
    assert np.sqrt(found.covariance[1, 1]) < 0.025
    # Its ends hidden behind something nearer (the rays past its last points blocked): the
    # face ends there in the scan, but not in the world. Along it, it stays as guessed.
    # (Two posts just in front of the scanner, out of the first gate's reach of the face.)
    blocked = _cast(walls, truth, extra=[WallBox((0.55, 0.08), (0.01, 0.046)),
                                         WallBox((0.55, -0.04), (0.01, 0.0576))], noise=0.003,
                    boxes=box)
    found = match_scan(walls, loc.points(_scan(0, blocked)), np.array(MOUNT[:2]),
                       (0.22, 0.08, 0.0), LOOSE)
    assert found is not None and found.pose[1] == pytest.approx(0.08, abs=0.01)


def test_what_is_not_in_the_map_is_left_out():
    walls = WallMap(POOL)
    truth = (1.4, -2.0, 0.5)
    # Another robot beside the pool, and a cube on the floor in front of the base.
    others = [WallBox((1.3, -1.2), (0.29, 0.2), 0.3), WallBox((1.9, -1.75), (0.025, 0.025))]
    loc = ScanLocalizer(walls, MOUNT, (0.32, 0.24))
    found = match_scan(walls, loc.points(_scan(0, _cast(walls, truth, others))),
                       np.array(MOUNT[:2]), (truth[0] - 0.05, truth[1] + 0.04, truth[2]), LOOSE)
    assert found is not None
    assert np.subtract(found.pose, truth) == pytest.approx((0, 0, 0), abs=0.005)


def test_the_localizer_corrects_drifting_odometry_at_each_scan_in_order():
    """A base drives 0.9 m past the pool's platform, its odometry reading 5 % long: the scans
    keep its pose to a few millimetres, where the odometry ends 45 mm off, and the estimate
    stays within three standard deviations of the truth all the way."""
    walls = WallMap(POOL)
    loc = ScanLocalizer(walls, MOUNT, (0.32, 0.24))
    stamps = [k * 33_333_333 for k in range(91)]
    truths = [(1.0 + 0.01 * k, -2.4, 0.6) for k in range(91)]
    odoms = [(1.0 + 0.0105 * k, -2.4, 0.6) for k in range(91)]
    loc.odometry(stamps[0], odoms[0])
    sigma_x = []
    for k in range(1, 91):
        if k % 3 == 1:
            # A scan half way between two odometry messages comes before the second: it is
            # matched once that is in, at the pose between them.
            half = (1.0 + 0.01 * (k - 0.5), -2.4, 0.6)
            loc.scan(_scan(stamps[k] - 16_666_666, _cast(walls, half, seed=k)))
            assert loc.matched == (k - 1) // 3
        loc.odometry(stamps[k], odoms[k])
        error = np.subtract(loc.located(odoms[k]), truths[k])
        sigma = np.sqrt(np.diag(loc.covariance))
        assert np.all(np.abs(error) <= 3.0 * sigma + 0.001), (k, error, sigma)
        sigma_x.append(sigma[0])
        if k == 45:                                 # the west face in view all the way
            assert error == pytest.approx((0, 0, 0), abs=0.005)
            assert odoms[k][0] - truths[k][0] == pytest.approx(0.0225)
    assert loc.matched == 30 and loc.unmatched == 0
    # Past the west face, the south face's west end keeps the place along it.
    assert np.subtract(loc.located(odoms[-1]), truths[-1]) == pytest.approx((0, 0, 0),
                                                                             abs=0.01)
    assert sigma_x[-1] < 0.01
    report = loc.report(odoms[-1])
    assert report.startswith('laser: odometry off by (-') and '30 scans matched, 0 not' in report
    # An odometry message older than the last is ignored; a scan of nothing leaves it all.
    here = loc.located(odoms[-1])
    loc.odometry(stamps[0], odoms[0])
    loc.scan(_scan(stamps[-1], np.full(RAYS, np.inf)))
    assert loc.unmatched == 1 and loc.located(odoms[-1]) == here


def test_compose_and_inverse():
    a, b = (1.0, -2.0, 0.7), (0.3, 0.4, -1.1)
    assert compose(inverse(a), compose(a, b)) == pytest.approx(b)
