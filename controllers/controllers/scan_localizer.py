"""Where a mobile base is, from its odometry and its laser scanner (no ROS).

Odometry drifts: a scale error of a few per cent puts a youBot centimetres off after each
drive, and the pool's drops go by where the controller believes the base stands. A laser
scanner sees the cell's fixed walls; matching each scan to them (the map: the world's
obstacles, their faces at the scanner's height) gives the base's pose in the cell. As AMCL or
slam_toolbox's localization mode do, the estimate is kept as a correction of the odometry (a
``map -> odom`` transform): the base's pose is the correction composed with its odometry, and
each matched scan renews the correction for the odometry at the scan's time (interpolated
between the two odometry messages around it).

The estimate is a Kalman filter's: the pose has a covariance, which grows with every metre
driven and radian turned as the odometry's drift allows (``DRIFT_PER_M``, ...), and each scan
is fused with the pose the odometry predicts by an iterated update: Gauss-Newton over the scan
points' distances to their wall faces (point-to-line ICP) and the prediction's own, weighted by
their covariances. A point is matched to the nearest wall face that faces the scanner (the
outer face of a thin wall, never its inner one), within a gate that narrows from 0.2 m to
3 cm. What the matched faces do not fix (along a single wall) stays where the odometry puts
it, with its uncertainty; a scan with too few points on the walls, or that does not fit them
(the RMS residual above ``MAX_RMS_M``), leaves the estimate as it was. Points on anything
else (a material, another robot, the base's own wheels) fall outside the gate and are not
used.
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, List, Optional, Sequence, Tuple

import numpy as np

Pose = Tuple[float, float, float]            # x, y, yaw in the cell

# The gates a scan point must be within of a wall face, one per Gauss-Newton iteration [m].
GATES_M = (0.2, 0.1, 0.05, 0.03, 0.03, 0.03)
# A face is matched only where the point's foot lies on it, or this far beyond its ends [m].
FACE_END_M = 0.01
# A scan is used only with this many points on the walls, fitting them this well [m].
MIN_POINTS = 8
MAX_RMS_M = 0.02
# Each point's distance from its face: the scanner's noise and the walls' as built [m]; and
# the points a scan counts as at most (its points' errors go together: AMCL uses 30 to 60
# of a scan's beams for the same reason).
POINT_SIGMA_M = 0.01
EFFECTIVE_POINTS = 30
# How far the odometry may be off: per metre driven (each axis) [m] and per radian turned
# (the heading; the coordinator's odometry_drift sets both), and per metre driven (the
# heading) [rad]; and how well the base knows its start pose.
DRIFT_PER_M = 0.05
TURN_DRIFT_PER_M = 0.01
START_SIGMA = (0.01, 0.01, 0.01)
# A correction of more than this, in one scan, is a wrong match, not drift [m, rad].
MAX_STEP_M, MAX_STEP_RAD = 0.25, 0.2
# A face's end seen in a scan (face_ends): a run of at least CORNER_RUN points on the face,
# its last within CORNER_NEAR_M of the end, the next ray CORNER_JUMP_M farther or empty; used
# once the gate is CORNER_GATE_M or narrower (the points on the right faces by then).
CORNER_RUN = 3
CORNER_NEAR_M = 0.06
CORNER_LINE_M = 0.02
CORNER_JUMP_M = 0.05
CORNER_GATE_M = 0.05
# A scan is fused only once the base has moved this far or turned this much since the last
# one, or this long after it [m, rad, ns].
UPDATE_MIN_M, UPDATE_MIN_RAD, UPDATE_MAX_NS = 0.01, 0.01, 1_000_000_000
# The odometry messages kept to find the base's odometry at a scan's time.
ODOM_HISTORY = 64


@dataclass(frozen=True)
class WallBox:
    """A fixed obstacle the scanner sees, as a box in the floor's plane: its centre, half its
    length and width, its yaw (a cylinder: its bounding polygon, polygon_box)."""

    center: Tuple[float, float]
    half: Tuple[float, float]
    yaw: float = 0.0


class WallMap:
    """The faces of the fixed obstacles at the scanner's height: segments with their outward
    normals."""

    def __init__(self, boxes: Sequence[WallBox], polygons: Sequence[np.ndarray] = ()) -> None:
        starts: List[np.ndarray] = []
        ends: List[np.ndarray] = []
        for poly in [box_corners(b) for b in boxes] + [np.asarray(p, float) for p in polygons]:
            # Counter-clockwise corners: each edge's outward normal is its direction turned
            # clockwise.
            if _signed_area(poly) < 0.0:
                poly = poly[::-1]
            starts.extend(poly)
            ends.extend(np.roll(poly, -1, axis=0))
        self.a = np.array(starts, float).reshape(-1, 2)
        self.b = np.array(ends, float).reshape(-1, 2)
        edge = self.b - self.a
        self.length = np.hypot(edge[:, 0], edge[:, 1])
        self.along = edge / np.maximum(self.length, 1e-12)[:, None]
        self.normal = np.stack([self.along[:, 1], -self.along[:, 0]], axis=1)

    def __len__(self) -> int:
        return len(self.a)

    def nearest(self, points: np.ndarray, sensor: np.ndarray, reach: float = 0.0
                ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For each point (N x 2): the signed distance to the nearest face that faces
        ``sensor`` and that its foot lies on (or ``reach`` [m] past its ends, at least
        FACE_END_M), that face (its index), its distance (inf where no face qualifies), and
        where its foot lies along the face from its start [m]."""
        if not len(self):
            return (np.zeros(len(points)), np.zeros(len(points), int),
                    np.full(len(points), np.inf), np.zeros(len(points)))
        rel = points[:, None, :] - self.a[None, :, :]                    # N x M x 2
        t = np.einsum('nmk,mk->nm', rel, self.along)
        signed = np.einsum('nmk,mk->nm', rel, self.normal)
        facing = ((sensor - self.a) * self.normal).sum(axis=1) > 0.0       # M
        reach = max(reach, FACE_END_M)
        on_face = (t >= -reach) & (t <= self.length[None, :] + reach)
        dist = np.where(on_face & facing[None, :], np.abs(signed), np.inf)
        best = np.argmin(dist, axis=1)
        rows = np.arange(len(points))
        return signed[rows, best], best, dist[rows, best], t[rows, best]


def box_corners(box: WallBox) -> np.ndarray:
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    hx, hy = box.half
    local = np.array([(hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy)])
    corners: np.ndarray = local @ np.array([[c, s], [-s, c]]) + np.asarray(box.center)
    return corners


def polygon_box(center: Tuple[float, float], radius: float, sides: int = 16) -> np.ndarray:
    """A cylinder's cross-section as the polygon around it (its faces touch the circle)."""
    r = radius / math.cos(math.pi / sides)
    a = np.arange(sides) * 2.0 * math.pi / sides
    return np.stack([center[0] + r * np.cos(a), center[1] + r * np.sin(a)], axis=1)


def _signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


@dataclass(frozen=True)
class ScanPoints:
    """A scan's points in base_link (N x 2), in the order of its rays; each point's ray and range
    [m]; whether the ray before it and the ray after it return nothing or something at least
    ``CORNER_JUMP_M`` farther (where a face the point lies on may end); and the angle between
    two rays [rad]."""

    xy: np.ndarray
    ray: np.ndarray                     # each point's ray (its index in the scan)
    ranges: np.ndarray
    far_before: np.ndarray
    far_after: np.ndarray
    step: float

    def __len__(self) -> int:
        return len(self.xy)


@dataclass(frozen=True)
class ScanMatch:
    """One scan fused with the pose it was expected at: the base's pose and its covariance
    (x, y [m], yaw [rad]), the points on the walls and their RMS distance from them [m]."""

    pose: Pose
    covariance: np.ndarray
    points: int
    rms: float


def _rotate(yaw: float, v: np.ndarray) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    turned: np.ndarray = v @ np.array([[c, s], [-s, c]])
    return turned


def _jacobian(direction: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """d(direction . point)/d(x, y, yaw) of points at ``arm`` from the base (both K x 2)."""
    return np.column_stack([direction,
                            direction[:, 1] * arm[:, 0] - direction[:, 0] * arm[:, 1]])


def face_ends(walls: WallMap, points: ScanPoints, face: np.ndarray, use: np.ndarray,
              at: np.ndarray, sensor: np.ndarray
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where the scan sees a face end: a run of at least CORNER_RUN points on a face, taken on
    from its last matched point through the next rays that stay on the face's line (within
    CORNER_LINE_M: the pose may be off along the face, and its points past the end it
    predicts are still the face's), to a ray that returns nothing or something farther (the
    face turned away: a corner, not something in front of it), within CORNER_NEAR_M of the
    face's end. Returns, for each, the residual along the face [m] (the corner is half a ray's
    spacing on the face past the last point), the face's direction there (away from the run),
    the last point (cell) and the residual's standard deviation [m]."""
    rs, dirs, pts, sigmas = [], [], [], []
    for m in np.unique(face[use]):
        run = np.flatnonzero(use & (face == m))
        if len(run) < CORNER_RUN:
            continue
        t = (at - walls.a[m]) @ walls.along[m]
        off_line = np.abs((at - walls.a[m]) @ walls.normal[m]) > CORNER_LINE_M
        for k, end, sign in ((run[np.argmin(t[run])], 0.0, -1.0),
                             (run[np.argmax(t[run])], float(walls.length[m]), 1.0)):
            # Which way along the rays the face goes on past k: where t moves towards the end.
            way = 0
            for d in (-1, 1):
                j = k + d
                if (0 <= j < len(points) and abs(int(points.ray[j]) - int(points.ray[k])) == 1
                        and not off_line[j] and sign * (t[j] - t[k]) > 0.0):
                    way = d
            if way == 0:
                # Nothing on the face's line past k: k ends it, if a ray's neighbour past it
                # is far (either side: the other one is the face's own run).
                inner = k - 1 if k > 0 and face[k - 1] == m and use[k - 1] else k + 1
                way = 1 if inner == k - 1 else -1
            else:
                while True:
                    j = k + way
                    if not (0 <= j < len(points)
                            and abs(int(points.ray[j]) - int(points.ray[k])) == 1
                            and not off_line[j] and sign * (t[j] - t[k]) > 0.0):
                        break
                    k = j
            if abs(t[k] - end) > CORNER_NEAR_M:
                continue
            if not (points.far_after[k] if way == 1 else points.far_before[k]):
                continue
            ray = at[k] - sensor
            rng = float(np.hypot(*ray))
            slant = abs(float(ray @ walls.normal[m])) / max(rng, 1e-9)
            spacing = rng * points.step / max(slant, 0.2)
            rs.append(sign * (t[k] - end) + 0.5 * spacing)
            dirs.append(sign * walls.along[m])
            pts.append(at[k])
            sigmas.append(math.hypot(spacing / math.sqrt(12.0), POINT_SIGMA_M))
    return (np.array(rs), np.array(dirs).reshape(-1, 2), np.array(pts).reshape(-1, 2),
            np.array(sigmas))


def match_scan(walls: WallMap, points: ScanPoints, sensor: np.ndarray, prior: Pose,
               prior_cov: np.ndarray) -> Optional[ScanMatch]:
    """The base's most likely pose given ``points`` on ``walls`` and the pose it was expected
    at, ``prior``, with covariance ``prior_cov``: Gauss-Newton on the points' distances to
    their faces, the face ends the scan sees (face_ends) and the prior (an iterated Kalman
    update). What they do not fix stays as the prior has it. ``sensor``: the scanner's
    position in base_link. None when the scan does not show enough of the walls, or does not
    fit them."""
    expected = np.array(prior, float)
    prior_info = np.linalg.inv(prior_cov)
    pose = expected.copy()
    info = np.zeros((3, 3))
    for gate in GATES_M:
        at = _rotate(pose[2], points.xy) + pose[:2]
        eye = _rotate(pose[2], sensor) + pose[:2]
        signed, face, dist, _ = walls.nearest(at, eye)
        use = dist < gate
        count = int(use.sum())
        if count < MIN_POINTS:
            return None
        jac = _jacobian(walls.normal[face[use]], at[use] - pose[:2])
        # The points' errors are not independent (the same wall, the same mount): a scan
        # counts as EFFECTIVE_POINTS of them at most, each with POINT_SIGMA_M.
        weight = min(1.0, EFFECTIVE_POINTS / count) / POINT_SIGMA_M ** 2
        info = weight * (jac.T @ jac)
        grad = weight * (jac.T @ signed[use])
        if gate <= CORNER_GATE_M:
            r, dirs, pts, sig = face_ends(walls, points, face, use, at, eye)
            if len(r):
                jac = _jacobian(dirs, pts - pose[:2]) / sig[:, None]
                info = info + jac.T @ jac
                grad = grad + jac.T @ (r / sig)
        step = -np.linalg.solve(info + prior_info, grad + prior_info @ (pose - expected))
        pose = pose + step
        if float(np.abs(step).max()) < 1e-5 and gate <= CORNER_GATE_M:
            break
    at = _rotate(pose[2], points.xy) + pose[:2]
    signed, _, dist, _ = walls.nearest(at, _rotate(pose[2], sensor) + pose[:2])
    use = dist < GATES_M[-1]
    count = int(use.sum())
    if count < MIN_POINTS:
        return None
    rms = float(np.sqrt(np.mean(signed[use] ** 2)))
    if rms > MAX_RMS_M:
        return None
    return ScanMatch((float(pose[0]), float(pose[1]), float(pose[2])),
                     np.linalg.inv(info + prior_info), count, rms)


def compose(a: Pose, b: Pose) -> Pose:
    """Pose ``b`` (in frame ``a``) in the frame ``a`` is given in."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def inverse(a: Pose) -> Pose:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


@dataclass(frozen=True)
class Scan:
    """A laser scan as sensor_msgs/LaserScan has it."""

    stamp_ns: int
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray


class ScanLocalizer:
    """One base's pose in the cell from its odometry and its scans. ``mount``: the scanner's
    pose in base_link (x, y, yaw); ``body``: half the base's length and width, and a margin
    [m] (its own wheels are not walls); ``drift``: how far its odometry may be off, per metre
    driven and per radian turned."""

    def __init__(self, walls: WallMap, mount: Pose, body: Tuple[float, float],
                 drift: float = DRIFT_PER_M) -> None:
        self.walls, self.mount, self.body, self.drift = walls, mount, body, drift
        self.correction: Pose = (0.0, 0.0, 0.0)
        self.covariance = np.diag(np.square(START_SIGMA))   # of the pose (x, y, yaw)
        self.last: Optional[ScanMatch] = None          # the last scan that matched
        self.matched = self.unmatched = self.skipped = 0
        self._fused: Optional[Tuple[Pose, int]] = None    # (odometry, stamp) of the last fused
        self._odom: Deque[Tuple[int, Pose]] = deque(maxlen=ODOM_HISTORY)
        self._stamps: Deque[int] = deque(maxlen=ODOM_HISTORY)
        self._scans: Deque[Scan] = deque()

    def located(self, odometry: Pose) -> Pose:
        """The base's pose in the cell, from its odometry's (in the cell's frame)."""
        return compose(self.correction, odometry)

    def report(self, odometry: Pose) -> str:
        """How the scans correct the odometry of a base at ``odometry``, in words (for the
        run's events): where the base is from where its odometry puts it."""
        x, y, yaw = self.located(odometry)
        dx, dy, dyaw = x - odometry[0], y - odometry[1], yaw - odometry[2]
        sx, sy, syaw = np.sqrt(np.diag(self.covariance))
        last = self.last
        fit = (f'; last fit {last.rms * 1000:.1f} mm rms over {last.points} points'
               if last is not None else '')
        return (f'laser: odometry off by ({dx * 1000:+.0f}, {dy * 1000:+.0f}) mm, '
                f'{math.degrees(dyaw):+.2f} deg, pose +- ({sx * 1000:.0f}, {sy * 1000:.0f}) '
                f'mm, {math.degrees(syaw):.2f} deg; {self.matched} scans matched, '
                f'{self.unmatched} not, {self.skipped} at rest{fit}')

    def located_velocity(self, velocity: Pose) -> Pose:
        """A velocity along the cell's axes as odometry gives it (vx, vy, wz), corrected."""
        c, s = math.cos(self.correction[2]), math.sin(self.correction[2])
        return (c * velocity[0] - s * velocity[1], s * velocity[0] + c * velocity[1],
                velocity[2])

    def odometry(self, stamp_ns: int, pose: Pose) -> None:
        """An odometry message (its pose in the cell's frame, uncorrected)."""
        if self._stamps and stamp_ns <= self._stamps[-1]:
            return
        if self._odom:
            self._predict(self._odom[-1][1], pose)
        self._odom.append((stamp_ns, pose))
        self._stamps.append(stamp_ns)
        self._take_scans()

    def scan(self, scan: Scan) -> None:
        """A scan: matched once the odometry at its time is in (scans in order)."""
        self._scans.append(scan)
        self._take_scans()

    def _predict(self, before: Pose, after: Pose) -> None:
        """The pose's covariance after the odometry moved from ``before`` to ``after``."""
        dx, dy, dyaw = compose(inverse(before), after)
        dyaw = math.remainder(dyaw, 2.0 * math.pi)
        driven = math.hypot(dx, dy)
        yaw = self.located(before)[2]
        c, s = math.cos(yaw), math.sin(yaw)
        move = np.eye(3)
        move[0, 2], move[1, 2] = -s * dx - c * dy, c * dx - s * dy
        cov = move @ self.covariance @ move.T
        # Odometry drifts by a scale error, the same on every step: its error grows with the
        # distance, not with its square root (a random walk of 30 steps a second would claim
        # a tenth of it after a metre). So the standard deviations grow by the drift.
        grow = np.array([self.drift * driven, self.drift * driven,
                         self.drift * abs(dyaw) + TURN_DRIFT_PER_M * driven])
        sigma = np.sqrt(np.diag(cov))
        scale = (sigma + grow) / np.maximum(sigma, 1e-9)
        self.covariance = cov * np.outer(scale, scale)

    def _take_scans(self) -> None:
        while self._scans and self._stamps and self._stamps[-1] >= self._scans[0].stamp_ns:
            scan = self._scans.popleft()
            odom = self._odometry_at(scan.stamp_ns)
            if odom is not None:
                self._update(scan, odom)

    def _odometry_at(self, stamp_ns: int) -> Optional[Pose]:
        k = bisect.bisect_left(list(self._stamps), stamp_ns)
        if k >= len(self._odom):
            return None
        t1, p1 = self._odom[k]
        if t1 == stamp_ns or k == 0:
            return p1 if t1 == stamp_ns else None
        t0, p0 = self._odom[k - 1]
        f = (stamp_ns - t0) / (t1 - t0)
        turn = math.remainder(p1[2] - p0[2], 2.0 * math.pi)
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * turn)

    def points(self, scan: Scan) -> ScanPoints:
        """The scan's points in base_link: its finite ranges within its limits, off the base
        itself, and where the rays beside each return nothing or something farther."""
        r = np.asarray(scan.ranges, float)
        angle = scan.angle_min + scan.angle_increment * np.arange(len(r)) + self.mount[2]
        hit = np.isfinite(r) & (r > scan.range_min) & (r < scan.range_max)
        far = np.where(hit, r, np.inf)
        r = np.where(hit, r, 0.0)
        pts = np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1) + np.array(
            self.mount[:2])
        off_body = (np.abs(pts[:, 0]) > self.body[0]) | (np.abs(pts[:, 1]) > self.body[1])
        keep = hit & off_body
        before = np.concatenate([[np.inf], far[:-1]]) >= far + CORNER_JUMP_M
        after = np.concatenate([far[1:], [np.inf]]) >= far + CORNER_JUMP_M
        return ScanPoints(pts[keep], np.flatnonzero(keep), r[keep], before[keep],
                          after[keep], abs(scan.angle_increment))

    def _update(self, scan: Scan, odom: Pose) -> None:
        # A base that has not moved since the last scan fused learns little from the next
        # (AMCL's update_min_d and update_min_a): at rest, one scan a second.
        if self._fused is not None:
            at, when = self._fused
            dx, dy, dyaw = compose(inverse(at), odom)
            if (math.hypot(dx, dy) < UPDATE_MIN_M and abs(math.remainder(dyaw, 2 * math.pi))
                    < UPDATE_MIN_RAD and scan.stamp_ns - when < UPDATE_MAX_NS):
                self.skipped += 1
                return
        prior = compose(self.correction, odom)
        found = match_scan(self.walls, self.points(scan), np.array(self.mount[:2]), prior,
                           self.covariance)
        if found is None or (math.hypot(found.pose[0] - prior[0], found.pose[1] - prior[1])
                             > MAX_STEP_M or abs(found.pose[2] - prior[2]) > MAX_STEP_RAD):
            self.unmatched += 1
            return
        self.matched += 1
        self._fused = (odom, scan.stamp_ns)
        self.last = found
        self.correction = compose(found.pose, inverse(odom))
        self.covariance = found.covariance
