"""The ways a fleet of youBots drives between its places, and the start-up checks that they can
share the floor (no ROS).

A youBot drives between four kinds of place: its park (its start pose, where it waits while
another is loaded), the loading pose by the arm (one youBot at a time), the pool's unload stands
(one youBot at a time) and the ways between them. A youBot standing at its park must never be in
another's way, so every way of every youBot keeps the cell's clearance from every other youBot's
park; a youBot at the loading pose or at a stand may be passed only by ways that keep clear of it
too. What is checked here, from the layout alone, the coordinator relies on while it drives.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import POOL, CellLayout, LayoutError, UnloadStand, pool_sides
from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.footprint import Footprint, clearance, polygon_distance

# The youBot's footprint: half its length and half its width over the wheels, about base_link
# [m] (its box 0.57 x 0.36, the wheels' outer faces 0.209 from base_link).
YOUBOT_HALF_LENGTH_M, YOUBOT_HALF_WIDTH_M = 0.29, 0.21
YOUBOT_FOOTPRINT = Footprint(YOUBOT_HALF_LENGTH_M, YOUBOT_HALF_WIDTH_M)
# A base following its path strays this far from it at most (the follower's error, a few
# centimetres on the cell's drives): ways are checked with this much more than the clearance.
TRACKING_MARGIN_M = 0.05
# The ways are checked at poses this far apart along them [m].
SWEEP_STEP_M = 0.05
# An obstacle this low is driven over (a marked area on the floor) [m].
OBSTACLE_LOW_M = 0.01
# A youBot leaving a stand for its park backs this far sideways off the stand's line, away from
# the pool, before it turns towards its park [m]: turning at once, on a way half way to a park
# north-east of the pool, its footprint swept over the corner of the pool's north wall.
STAND_BACK_OFF_M = 0.15


def obstacle_height(o: Any) -> float:
    """An obstacle's height (world_description's ObstacleConfig) [m]."""
    return float(o.size[2] if o.shape == 'box' else o.size[-1] if o.shape == 'cylinder'
                 else 2 * o.size[0])


def way_back(stands: Sequence[UnloadStand], to: Pose2D,
             exit: Sequence[Sequence[float]] = ()) -> Tuple[Tuple[float, ...], ...]:
    """The via points of the drive from the stands to ``to`` (the loading pose, or a park):
    half way between it and the right stand, where the base turns round on its way; from a
    side with ``exit`` points (past the pool's corner; the west has none), those instead."""
    if exit:
        return tuple(tuple(p) for p in exit)
    right = next(st for st in stands if st.row == -1)
    return ((0.5 * (to[0] + right.pose[0]), 0.5 * (to[1] + right.pose[1]), 0.0),)


def way_off(layout: CellLayout, stand: UnloadStand, to: Pose2D) -> Tuple[Tuple[float, ...], ...]:
    """The via points of the drive from ``stand`` to ``to`` (the loading pose, or a park):
    way_back's from its side of the pool; from a side with ``exit`` points, first
    STAND_BACK_OFF_M sideways off the stand's line (turning at once, a base at the east side's
    stand facing north swept its corners over the pool's wall)."""
    side = pool_sides(layout)[stand.side]
    back = way_back([st for st in layout.stands if st.side == stand.side], to, side.exit)
    return (_backed_off(layout, stand), *back) if side.exit else back


def way_between(layout: CellLayout, stand: UnloadStand) -> Tuple[Tuple[float, ...], ...]:
    """The via points of the drive between ``stand`` and the other of its side of the pool."""
    return pool_sides(layout)[stand.side].turn


def _backed_off(layout: CellLayout, stand: UnloadStand) -> Tuple[float, float, float]:
    """The point STAND_BACK_OFF_M sideways off ``stand``'s line, away from the pool."""
    x, y, yaw = stand.pose
    side = np.array([-math.sin(yaw), math.cos(yaw)])
    if side @ (np.asarray(layout.regions[POOL].center, float) - (x, y)) > 0.0:
        side = -side
    return (x + STAND_BACK_OFF_M * side[0], y + STAND_BACK_OFF_M * side[1], 0.0)


def way_to_park(layout: CellLayout, stand: UnloadStand,
                park: Pose2D) -> Tuple[Tuple[float, ...], ...]:
    """The via points of the drive from ``stand`` to ``park``: first STAND_BACK_OFF_M
    sideways off the stand's line, away from the pool, then way_back's (way_off)."""
    way = way_off(layout, stand, park)
    return way if pool_sides(layout)[stand.side].exit else (_backed_off(layout, stand), *way)


def route_poses(start: Pose2D, goal: Pose2D, via: Sequence[Sequence[float]] = (),
                step: float = SWEEP_STEP_M) -> np.ndarray:
    """The poses a base passes through on the way from ``start`` through ``via`` to ``goal``:
    the path's points, the heading turned in step with the distance travelled (the follower
    turns it over the drive's time, on a profile of the same shape)."""
    path = BezierPath(key_poses_between(start, goal, via))
    count = max(2, int(math.ceil(path.length / step)) + 1)
    s = np.linspace(0.0, path.length, count)
    xy = np.array([path.pose(v)[:2] for v in s])
    yaw = path.key_poses[0][2] + path.heading_sweep * s / max(path.length, 1e-9)
    return np.column_stack([xy, yaw])


def _ways(layout: CellLayout, robot: str) -> Dict[str, np.ndarray]:
    """A youBot's ways, by name: from its park to the loading pose, out to each stand of its
    side of the pool, between them, and back to the loading pose and to its park."""
    bay, park = layout.youbot_home, layout.park(robot)
    # (A youBot parked at the loading pose, as one alone is, has no ways to its park.)
    parked = not np.allclose(park, bay)
    ways = {'its park to the loading pose': route_poses(park, bay)} if parked else {}
    for st in layout.stands_of(robot):
        ways[f'the loading pose to {st.name}'] = route_poses(bay, st.pose, layout.way_out(st.name))
        ways[f'{st.name} to the loading pose'] = route_poses(st.pose, bay,
                                                             way_off(layout, st, bay))
        if parked:
            ways[f'{st.name} to its park'] = route_poses(st.pose, park,
                                                         way_to_park(layout, st, park))
        for other in layout.stands_of(robot):
            if other is not st:
                ways[f'{st.name} to {other.name}'] = route_poses(st.pose, other.pose,
                                                                 way_between(layout, st))
    return ways


def check_fleet(layout: CellLayout, obstacles: Sequence[Any], loading_given: bool,
                conveyor: Optional[Any] = None) -> None:
    """A LayoutError (one line, naming the robot) unless the cell's youBots, one or several,
    can share the floor: each park (its start pose) and the loading pose off the obstacles and
    the conveyor, and each youBot's ways off them; and for a fleet, the loading pose given
    apart from the parks, the parks apart, each youBot's ways clear of the other youBots'
    parks, its way to its park clear of the loading pose and its way to the loading pose clear
    of the stands (with the cell's clearance)."""
    bay = np.array([layout.youbot_home])
    parks = {r.name: np.array([layout.park(r.name)]) for r in layout.transports}
    boxes = _obstacle_boxes(obstacles) + _conveyor_box(conveyor)
    for name, park in parks.items():
        hit = next((o for o, box in boxes if _box_clearance(park, box) <= 0.0), None)
        if hit is not None:
            raise LayoutError(f'robot {name}: its start pose overlaps obstacle {hit}')
    hit = next((o for o, box in boxes if _box_clearance(bay, box) <= 0.0), None)
    if hit is not None:
        raise LayoutError(f'the loading pose (where a youBot is loaded) overlaps obstacle {hit}')
    ways = {name: _ways(layout, name) for name in parks}
    if layout.fleet:
        _check_shared_floor(layout, parks, ways, bay, loading_given)
    # (Then the obstacles: a way that is in another's way is named for that first.)
    _check_off_the_obstacles(ways, boxes)


def _check_shared_floor(layout: CellLayout, parks: Dict[str, np.ndarray],
                        ways: Dict[str, Dict[str, np.ndarray]], bay: np.ndarray,
                        loading_given: bool) -> None:
    """check_fleet's rules for two youBots or more."""
    fp, gap = YOUBOT_FOOTPRINT, layout.clearance
    if not loading_given:
        raise LayoutError(f'the cell has {len(layout.transports)} youBots: its cell section '
                          'gives the loading pose (cell.loading: x, y, yaw), apart from their '
                          'start poses, where each waits while another is loaded')
    for name, park in parks.items():
        if clearance(park, fp, bay, fp) < gap:
            raise LayoutError(f'robot {name}: its start pose is within {gap:g} m of the loading '
                              'pose (cell.loading): it waits there while another is loaded')
        for other, there in parks.items():
            if other < name and clearance(park, fp, there, fp) < gap:
                raise LayoutError(f'robot {name}: its start pose is within {gap:g} m of '
                                  f'{other}\'s')
    stands = np.array([st.pose for st in layout.stands])
    for name in parks:
        for way, poses in ways[name].items():
            keep: List[Tuple[str, np.ndarray]] = [
                (f'{other}\'s start pose', there) for other, there in parks.items()
                if other != name]
            if way.endswith('its park'):
                keep.append(('the loading pose', bay))
            if way == 'its park to the loading pose':
                keep.append(('the unload stands', stands))
            for what, where in keep:
                d = clearance(poses, fp, where, fp)
                if d < gap + TRACKING_MARGIN_M:
                    raise LayoutError(
                        f'robot {name}: its way from {way} passes {max(d, 0.0):.2f} m from '
                        f'{what} (the cell keeps {gap:g} m, and {TRACKING_MARGIN_M:g} m more '
                        'for the drive\'s errors)')


def _check_off_the_obstacles(ways: Dict[str, Dict[str, np.ndarray]],
                             boxes: List[Tuple[str, np.ndarray]]) -> None:
    """A LayoutError unless every youBot's every way (``ways``, by robot and way) keeps its
    footprint off every obstacle's (``boxes``)."""
    for name, theirs in ways.items():
        for way, poses in theirs.items():
            hit = next((o for o, box in boxes if _box_clearance(poses, box) <= 0.0), None)
            if hit is not None:
                raise LayoutError(f'robot {name}: its way from {way} runs over obstacle {hit} '
                                  '(its footprint over the wheels)')


def keeps_clear(layout: CellLayout, way: np.ndarray, others: Sequence[np.ndarray]) -> bool:
    """Whether a base on ``way`` (poses) keeps the cell's clearance, and TRACKING_MARGIN_M more,
    from each of ``others`` (each the poses another base stands at or passes through): the
    rule every drive of a fleet obeys (the coordinator's traffic rules)."""
    keep = layout.clearance + TRACKING_MARGIN_M
    return all(clearance(way, YOUBOT_FOOTPRINT, there, YOUBOT_FOOTPRINT) >= keep
               for there in others)


def _obstacle_boxes(obstacles: Sequence[Any]) -> List[Tuple[str, np.ndarray]]:
    """The obstacles a base cannot drive over, as (name, corners)."""
    out = []
    for o in obstacles:
        if not o.collision or o.position[2] + obstacle_height(o) / 2 <= OBSTACLE_LOW_M:
            continue
        half = (o.size[0] / 2, o.size[1] / 2) if o.shape == 'box' else (o.size[0], o.size[0])
        corners = Footprint(*half).corners((o.position[0], o.position[1], o.yaw))
        out.append((o.name or o.shape, corners))
    return out


def check_loader_base(layout: CellLayout, obstacles: Sequence[Any],
                      conveyor: Optional[Any] = None) -> None:
    """A LayoutError unless the loader's base stands on the floor, or on top of what is under
    it (a pedestal), not inside an obstacle or the conveyor."""
    x, y, z, _ = layout.loader_base
    tops = {o.name or o.shape: o.position[2] + obstacle_height(o) / 2 for o in obstacles}
    if conveyor is not None:
        tops['conveyor'] = conveyor.position[2]
    for name, box in _obstacle_boxes(obstacles) + _conveyor_box(conveyor):
        if (tops.get(name, math.inf) > z + OBSTACLE_LOW_M
                and polygon_distance(Footprint(1e-3, 1e-3).corners((x, y, 0.0)), box) <= 0.0):
            raise LayoutError(f'robot {layout.loader.name}: its base stands inside obstacle '
                              f'{name}')


def _conveyor_box(conveyor: Optional[Any]) -> List[Tuple[str, np.ndarray]]:
    """The conveyor's frame, from the floor up to its belt, as an obstacle (name, corners)."""
    if conveyor is None:
        return []
    corners = Footprint(conveyor.length / 2, conveyor.width / 2).corners(
        (conveyor.position[0], conveyor.position[1], conveyor.yaw))
    return [('conveyor', corners)]


def _box_clearance(poses: np.ndarray, corners: np.ndarray) -> float:
    return min(polygon_distance(YOUBOT_FOOTPRINT.corners(p), corners) for p in poses)
