"""The cell's layout read from a world file (no ROS): the belt, the youBot's home and plate, the
pool's stands and their drop spots (each checked against what the youBot's arm reaches and
holds), each class's destination laid out in slots, and the checks that the cell's rules can
work (a LayoutError in one line otherwise). The layout itself is layout.py's ``CellLayout``."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Set, Tuple

import numpy as np

from cell_layout.arm_models import ArmModelError, arm_model
from cell_layout.fleet_routes import (
    OBSTACLE_LOW_M,
    YOUBOT_HALF_LENGTH_M,
    YOUBOT_HALF_WIDTH_M,
    check_fleet,
    check_loader_base,
    obstacle_height,
    way_back,
)
from cell_layout.layout import (
    ARM_CONTROLLER,
    PLATE_TOP_IN_BASE_M,
    POOL,
    CellLayout,
    CellRobot,
    LayoutError,
    PoolSide,
    Region,
    Rule,
    UnloadStand,
    fixed_boxes,
    plate_grid,
    slot_grid,
    world_to_base,
)
from cell_layout.loader_reach import with_pick_window
from controllers import youbot_arm
from controllers.bezier import Pose2D
from controllers.youbot_arm import ARM_BASE_IN_BASE_LINK_M


def with_extra_materials(world: Any, extra: Sequence[str]) -> Any:
    """The world (world_description.world_config.WorldConfig) with a batch larger by one
    material of each class named in ``extra`` (materials spawned beside the plan's)."""
    if not extra:
        return world
    if world.materials is None:
        raise LayoutError('extra materials: the world has no materials')
    known = {c.name for c in world.materials.classes}
    unknown = sorted(set(extra) - known)
    if unknown:
        raise LayoutError(f'extra materials {unknown}: no such class (classes: '
                          f'{", ".join(sorted(known))})')
    classes = tuple(replace(c, count=c.count + list(extra).count(c.name))
                    for c in world.materials.classes)
    return replace(world, materials=replace(world.materials, classes=classes))


def _robots(world: Any) -> Tuple[CellRobot, Tuple[CellRobot, ...]]:
    """The loader and the transports, as the world's roles name them (the paper's robots
    without a ``cell`` section), each with its arm's model; a LayoutError (one line) for robots
    this controller cannot drive: the loader may be any serial arm its URDF describes, the
    transports are youBots (their arm's joints are the youBot's)."""
    roles = world.roles
    names = sorted(r.name for r in world.robots)
    missing = [n for n in (roles.loader, *roles.transports) if n not in names]
    if missing:
        raise LayoutError(f'the cell needs its loader {roles.loader} and transports '
                          f'{list(roles.transports)} (the world\'s cell section names them), '
                          f'the world has {names}')
    base_dir = Path(world.source).parent if world.source else None
    out = []
    for name in (roles.loader, *roles.transports):
        robot = world.robot(name)
        arm = next((c for c in robot.controllers if c.name == ARM_CONTROLLER), None)
        if arm is None:
            raise LayoutError(f'robot {name}: it has no {ARM_CONTROLLER} (the arm the '
                              'coordinator moves)')
        if name != roles.loader and tuple(arm.joints) != tuple(youbot_arm.JOINT_NAMES):
            raise LayoutError(f'robot {name}: its {ARM_CONTROLLER} must drive '
                              f'{list(youbot_arm.JOINT_NAMES)} (a transport is a youBot)')
        if robot.suction is None:
            raise LayoutError(f'robot {name}: it has no grip tool (suction)')
        try:
            model = arm_model(robot, base_dir)
        except ArmModelError as exc:
            raise LayoutError(str(exc)) from None
        ns = robot.namespace
        out.append(CellRobot(name, ns, tuple(arm.joints),
                             f'/{ns}/{robot.suction.service}' if ns
                             else f'/{robot.suction.service}', model))
    first = world.robot(roles.transports[0]).pose.z
    for name in roles.transports:
        if abs(world.robot(name).pose.z - first) > 1e-3:
            raise LayoutError(f'robot {name}: it stands {world.robot(name).pose.z:g} m high, '
                              f'the first youBot {first:g} m: the fleet\'s youBots are alike')
    return out[0], tuple(out[1:])


def _parks_apart(loading: Any, start: Any, transports: Sequence[Any]) -> bool:
    """Whether the youBots wait at parks apart from the loading pose: several of them, or one
    that starts away from the loading pose the world gives (a fleet of one)."""
    if len(transports) > 1:
        return True
    return loading is not None and (
        math.hypot(loading[0] - start.x, loading[1] - start.y) > 1e-3
        or abs(math.remainder(loading[2] - start.yaw, math.tau)) > 1e-3)


def layout_from_world(world: Any) -> CellLayout:
    """The layout of a loaded WorldConfig (world_description.world_config) of the pipeline
    cell; a LayoutError (one line) for a cell whose rules cannot work."""
    if world.conveyor is None or world.materials is None:
        raise LayoutError('the world has no conveyor with materials')
    named = {o.name: o for o in world.obstacles if o.name}
    loader, transports = _robots(world)
    if POOL not in named:
        raise LayoutError(f'the world has no obstacle named {POOL}: the youBot unloads from '
                          'stands beside the pool')
    conv = world.conveyor
    if abs(math.sin(conv.yaw)) > 1e-9 or math.cos(conv.yaw) < 0.0:
        raise LayoutError('the coordinator expects the belt to carry along +x (yaw 0)')
    yb = world.robot(transports[0].name).pose
    zu = world.robot(loader.name).pose
    mats = world.materials
    rules = {c.name: Rule(c.name, c.destination, c.route, c.size, c.mass) for c in mats.classes}
    stands = tuple(replace(st, slide=stand_slide(st.pose, world.obstacles, world.floor_size))
                   for st in _stands(named[POOL], rules))
    more_sides: Tuple[PoolSide, ...] = ()
    if len(transports) > 1:
        # A fleet unloads at the pool's east side too, where the floor there is free.
        east, ways = _east_side(named[POOL], stands)
        if all(stand_clear(st.pose, world.obstacles, world.floor_size) for st in east):
            stands += tuple(replace(st, slide=stand_slide(st.pose, world.obstacles,
                                                          world.floor_size)) for st in east)
            more_sides = (ways,)
    into_pool = sum(c.count for c in mats.classes if c.destination == POOL)
    # (A spare spot per stand: one the arm cannot reach as the base stands is swapped for it.)
    heaviest = max((c.mass for c in mats.classes if c.destination == POOL), default=0.0)
    stands = _pool_drops(stands, named[POOL], yb.z, into_pool + len(stands), heaviest)
    roles = world.roles
    home = roles.loading if roles.loading is not None else (yb.x, yb.y, yb.yaw)
    side_x, py = stands[0].pose[0], named[POOL].position[1]
    layout = CellLayout(
        belt_y=conv.position[1], belt_top=conv.position[2],
        belt_end_x=conv.position[0] + conv.length / 2, belt_speed=conv.belt_speed,
        belt_encoder=conv.encoder.resolution if conv.encoder is not None else 0.0,
        belt_start_x=conv.position[0] - conv.length / 2,
        belt_width=conv.width,
        end_stop=conv.end_stop, swing_clearance=roles.swing_clearance,
        link_clearance=roles.link_clearance,
        material_size=mats.largest, manifest=dict(mats.counts),
        youbot_home=home, youbot_base_z=yb.z, loader_base=(zu.x, zu.y, zu.z, zu.yaw),
        rules=rules, stands=stands,
        plate_slots=plate_grid(max((r.size for r in rules.values() if r.route == 'carry'),
                                   default=0.0)),
        # Out: down to the first stand from the north-west (never east of it, so never
        # nearer the wall), facing south as it parks: through a point 15 cm west of it, from
        # which the path comes in along the wall (from 10 cm, it bowed 1 cm past the stand
        # towards the wall, and 2 cm more with 0.2 s of delay between odometry and command);
        # between the stands it turns about 0.3 m off the wall (its corners sweep 0.34 m
        # about base_link); back home it turns round on the way.
        via_out=((side_x - 0.15, py + 0.55, -math.pi / 2),),
        via_turn=((side_x - 0.3, py - 0.12, 0.0),),
        via_back=way_back(stands, home),
        loader=loader, transports=transports, clearance=roles.clearance,
        trip_load=roles.trip_load, more_sides=more_sides, fixed=fixed_boxes(world.obstacles),
        parks=tuple((r.pose.x, r.pose.y, r.pose.yaw) for r in map(world.robot, (
            t.name for t in transports))) if _parks_apart(roles.loading, yb, transports)
        else ())
    check_loader_base(layout, world.obstacles, world.conveyor)     # (before its links' checks)
    regions: Dict[str, Region] = {}
    served: Dict[str, Set[str]] = {}
    for dest in sorted({r.destination for r in rules.values()}):
        regions[dest], by = _region(layout, named[dest], dest)
        if by:
            served.setdefault(by, set()).add(dest)
    layout = replace(layout, regions=regions, stands=tuple(
        replace(st, serves=st.serves | frozenset(served.get(st.name, ()))) for st in stands))
    _check_capacity(layout)
    check_fleet(layout, world.obstacles, roles.loading is not None, world.conveyor)
    return with_pick_window(layout)


def _stands(pool: Any, rules: Dict[str, Rule]) -> Tuple[UnloadStand, ...]:
    """The youBot unloads from two stands west of the pool, side-on to it (Mecanum: it can stand
    any way round): facing south (the pool on its left) for the left row of its plate, then
    facing north (the pool on its right) for the right row. Its wheels (0.209 m from base_link;
    its side 0.18 m) stay 3.1 cm off the pool's west wall (its face 2 cm inside wall_x): at
    2.1 cm, the base's overshoot on a loaded machine touched it (real time: 1.5 cm and 3 degrees
    past the stand); each centimetre further costs a run about 0.25 s (the arm reaches further).
    Each pool material has its own drop spot, 7-15 cm inside the wall and 10 cm from the next:
    a cube dropped onto another can tumble back over the wall. A carried class's other
    destination (the paper's platform) is unloaded from the stand nearer it."""
    px, py = pool.position[0], pool.position[1]
    half = min(pool.size[0], pool.size[1]) / 2
    wall_x = px - half
    side_x = wall_x - 0.26
    right = UnloadStand('pool_right', (side_x, py + 0.05, math.pi / 2), -1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, 0.18), (0.07, 0.08), (0.15, 0.13), (0.07, -0.02))), frozenset({POOL}))
    left = UnloadStand('pool_left', (side_x, py - 0.3, -math.pi / 2), 1, tuple(
        np.array([wall_x + dx, py + dy, 0.2]) for dx, dy in
        ((0.07, -0.22), (0.07, -0.15), (0.15, -0.2), (0.15, -0.12))), frozenset({POOL}))
    return (left, right)


# The ways to and from the pool's east side pass this far north of its wall (base_link), from
# over its west wall to 15 cm east of the east side's stands [m]: over its centre instead, the
# way out came within 0.13 m of the example's park north-east of the loading pose, and the way
# back from the stand facing north swept a corner over the pool's north-east corner.
EAST_NORTH_M = 0.45


def _east_side(pool: Any, west: Tuple[UnloadStand, ...]
               ) -> Tuple[Tuple[UnloadStand, ...], PoolSide]:
    """The pool's east side, where a fleet's second youBot unloads while the first unloads
    at the west: the west's stands and their drop spots turned half round about the pool's
    centre (so the arm's every reach from them is the same), the one facing south first (it is
    reached from the north, past the pool's north-east corner: out over the pool's north wall
    (EAST_NORTH_M) to a point 15 cm east of the stands' line, as the west's way out; back the
    same way, backed off the stand first: fleet_routes.way_off). They unload into the pool
    only."""
    px, py = pool.position[0], pool.position[1]

    def turned(x: float, y: float) -> Tuple[float, float]:
        return 2 * px - x, 2 * py - y

    stands = []
    for st in sorted(west, key=lambda st: st.row):          # (the right row's first)
        x, y = turned(st.pose[0], st.pose[1])
        stands.append(UnloadStand(
            st.name.replace('pool_', 'pool_east_'), (x, y, math.remainder(st.pose[2] + math.pi,
                                                                           2 * math.pi)),
            st.row, tuple(np.array([*turned(d[0], d[1]), d[2]]) for d in st.drops),
            frozenset({POOL}), side=1))
    east_x = stands[0].pose[0]
    west_turn = (west[0].pose[0] - 0.3, py - 0.12)
    half = min(pool.size[0], pool.size[1]) / 2
    north = py + half + EAST_NORTH_M
    out = ((px - half, north, -math.pi / 2), (east_x + 0.15, north, -math.pi / 2))
    turn = ((*turned(*west_turn), math.pi),)
    return tuple(stands), PoolSide(out=out, out_turn=(*out, *turn), turn=turn,
                                   exit=out[::-1])


# A stand's base slides along its heading at most this far either way [m], keeping this far
# from any obstacle ahead or behind, and this far to its sides (a stand beside the pool's wall
# has 3.1 cm there) [m].
STAND_SLIDE_MAX_M = 0.5
STAND_SLIDE_STEP_M = 0.01
STAND_CLEAR_AHEAD_M, STAND_CLEAR_SIDE_M = 0.05, 0.01


def stand_clear(pose: Pose2D, obstacles: Sequence[Any], floor_size: float,
                along: float = 0.0) -> bool:
    """Whether a base standing at ``pose`` slid ``along`` its heading is on the floor and its
    footprint (with its clearances) clear of every obstacle that stands higher than
    OBSTACLE_LOW_M."""
    x, y, yaw = pose
    half = (YOUBOT_HALF_LENGTH_M + STAND_CLEAR_AHEAD_M, YOUBOT_HALF_WIDTH_M + STAND_CLEAR_SIDE_M)
    at = (x + along * math.cos(yaw), y + along * math.sin(yaw))
    if max(abs(at[0]), abs(at[1])) + math.hypot(*half) > floor_size / 2:
        return False
    return not any(_overlap((at, yaw, half), _footprint(o)) for o in obstacles
                   if o.collision and o.position[2] + obstacle_height(o) / 2 > OBSTACLE_LOW_M)


def stand_slide(pose: Pose2D, obstacles: Sequence[Any], floor_size: float
                ) -> Tuple[float, float]:
    """How far a base standing at ``pose`` may slide along its heading, back (negative) and
    forth, in STAND_SLIDE_STEP_M steps up to STAND_SLIDE_MAX_M, its footprint (with its
    clearances) clear of every obstacle that stands higher than OBSTACLE_LOW_M and on the
    floor; (0, 0) if it is not clear where it stands."""
    def clear(along: float) -> bool:
        return stand_clear(pose, obstacles, floor_size, along)

    if not clear(0.0):
        return (0.0, 0.0)
    ends = []
    for sign in (-1.0, 1.0):
        along = 0.0
        while along < STAND_SLIDE_MAX_M - 1e-9 and clear(sign * (along + STAND_SLIDE_STEP_M)):
            along = round(along + STAND_SLIDE_STEP_M, 6)
        ends.append(sign * along)
    return (ends[0], ends[1])


def _footprint(o: Any) -> Tuple[Tuple[float, float], float, Tuple[float, float]]:
    """An obstacle's outline on the floor: centre, yaw and half extents (a round one's
    bounding square)."""
    if o.shape == 'box':
        half = (o.size[0] / 2, o.size[1] / 2)
    else:
        half = (o.size[0], o.size[0])
    return ((o.position[0], o.position[1]), o.yaw, half)


def _overlap(a: Any, b: Any) -> bool:
    """Whether two rectangles (centre, yaw, half extents) overlap (separating axes)."""
    axes = []
    corners = []
    for (cx, cy), yaw, (hx, hy) in (a, b):
        u, v = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
        axes += [u, v]
        corners.append([np.array([cx, cy]) + i * hx * u + j * hy * v
                        for i in (-1, 1) for j in (-1, 1)])
    for axis in axes:
        pa = [float(p @ axis) for p in corners[0]]
        pb = [float(p @ axis) for p in corners[1]]
        if max(pa) <= min(pb) or max(pb) <= min(pa):
            return False
    return True


# The youBot grips a material's top face with its TCP this far above it (its fingertips reach
# 10.4 mm beyond it) [m].
GRASP_STANDOFF_M = 0.0104 + 0.002
# More drop spots in the pool, when a batch brings more than the stands' eight: a grid this far
# apart, this far in from its walls [m], each in the arm's reach from the nearer stand.
POOL_DROP_PITCH_M = 0.07
POOL_DROP_EDGE_M = 0.07
POOL_DROP_MARGIN_M = 0.03


def _pool_drops(stands: Tuple[UnloadStand, ...], pool: Any, base_z: float, needed: int,
                mass: float) -> Tuple[UnloadStand, ...]:
    """The stands with the drop spots their arm reaches: their own, and more after them
    (nearest the wall first) until the pool has ``needed``, none nearer than POOL_DROP_PITCH_M
    to another, each in reach from its stand with a margin (at a tilt of its own: what is let
    go over the pool need not stay level), the arm holding ``mass`` kg there at rest: from the
    stand, or from the base slid along its line abeam the spot (UnloadStand.abeam)."""
    seen: Dict[Tuple[str, float, float, float], bool] = {}

    def reached(stand: UnloadStand, point: np.ndarray, margin: float) -> bool:
        key = (stand.name, round(float(point[0]), 6), round(float(point[1]), 6), margin)
        if key not in seen:
            seen[key] = _youbot_reaches_from(stand, point, base_z, margin, mass)
        return seen[key]

    stands = tuple(replace(st, drops=tuple(d for d in st.drops if reached(st, d, 0.0)))
                   for st in stands)
    if all(len(st.drops) >= needed / len(stands) for st in stands):
        return stands
    # Too few: more spots after the stands' own; if that still leaves the pool short (a heavy
    # class is held out only near the wall), spots on a grid of their own instead.
    drops = _more_drops(stands, pool, needed, reached, {st.name: list(st.drops) for st in stands})
    if sum(len(d) for d in drops.values()) < needed:
        fresh = _more_drops(stands, pool, needed, reached, {st.name: [] for st in stands})
        if sum(len(d) for d in fresh.values()) > sum(len(d) for d in drops.values()):
            drops = fresh
    return tuple(replace(st, drops=tuple(drops[st.name])) for st in stands)


def _more_drops(stands: Tuple[UnloadStand, ...], pool: Any, needed: int, reached: Any,
                drops: Dict[str, List[np.ndarray]]) -> Dict[str, List[np.ndarray]]:
    """``drops`` (per stand) with spots added from a fine grid over the pool, the wall's side
    first (the arm's reach), until there are ``needed``: none nearer than POOL_DROP_PITCH_M to
    another, each for the stand with fewest that ``reached`` (stand, point, margin) it."""
    px, py = pool.position[0], pool.position[1]
    hx, hy = pool.size[0] / 2, pool.size[1] / 2
    step = POOL_DROP_PITCH_M / 4                 # (candidates on a finer grid, taken greedily)
    xs = np.arange(px - hx + POOL_DROP_EDGE_M, px + hx - POOL_DROP_EDGE_M + 1e-9, step)
    ys = np.arange(py - hy + POOL_DROP_EDGE_M, py + hy - POOL_DROP_EDGE_M + 1e-9, step)
    have = sum(len(d) for d in drops.values())
    for x in xs:
        for y in ys:
            if have >= needed:
                return drops
            point = np.array([x, y, 0.2])
            if any(np.linalg.norm(point[:2] - d[:2]) < POOL_DROP_PITCH_M - 1e-9
                   for ds in drops.values() for d in ds):
                continue
            # (A stand with fewer first, then the nearer.)
            for stand in sorted(stands, key=lambda st: (len(drops[st.name]),
                                                        abs(st.pose[1] - y))):
                if reached(stand, point, POOL_DROP_MARGIN_M):
                    drops[stand.name].append(point)
                    have += 1
                    break
    return drops


def _youbot_reaches_from(stand: UnloadStand, point: np.ndarray, base_z: float, margin: float,
                         mass: float, over: float = 0.06) -> bool:
    """Whether the youBot's arm reaches ``point`` (world) and ``over`` above it, from
    ``stand`` or slid along its line abeam the point: ``margin`` [m] further out from the arm's
    base too (the base stands a centimetre or two off its goal), and holding ``mass`` kg there
    at rest (within youbot_holds' share of each joint's effort)."""
    from cell_layout.reach import youbot_reaches
    up = np.array([0.0, 0.0, over])
    poses = [stand.pose]
    if stand.abeam(point) != tuple(stand.pose):
        poses.append(stand.abeam(point))
    for pose in poses:
        local = world_to_base(pose, point)
        local[2] -= base_z
        out = local[:2] - np.asarray(ARM_BASE_IN_BASE_LINK_M[:2])
        out = np.append(out / max(np.linalg.norm(out), 1e-9) * margin, 0.0)
        if (youbot_reaches([local + out + up, local + out])
                and youbot_reaches([local + up, local], mass)):
            return True
    return False


def _check_plate_load(layout: CellLayout, name: str, size: float, mass: float) -> None:
    """A LayoutError unless the youBot's arm holds ``mass`` kg at rest (within youbot_holds'
    share of each joint's effort) over one of the plate's slots, where it lifts every carried
    material from: a load it cannot hold there it cannot unload anywhere."""
    from cell_layout.reach import YOUBOT_LOAD_MAX, youbot_least_need
    best: Optional[Tuple[str, float, float]] = None
    for slot in layout.plate_slots:
        top = np.array([slot[0], slot[1], PLATE_TOP_IN_BASE_M + size])
        need = youbot_least_need([top + np.array([0.0, 0.0, 0.06]), top], mass)
        if need is not None and (best is None or need[1] / need[2] < best[1] / best[2]):
            best = need
    if best is not None and best[1] > YOUBOT_LOAD_MAX * best[2]:
        joint, torque, effort = best
        raise LayoutError(f'{name} materials ({mass:g} kg) are more than the youBot\'s arm '
                          f'holds at rest over its plate: {joint} needs {torque:.2f} N m there '
                          f'at best, and takes at most {YOUBOT_LOAD_MAX:.0%} of its '
                          f'{effort:g} N m (the rest accelerates it)')


def _region(layout: CellLayout, obstacle: Any, name: str) -> Tuple[Region, str]:
    """A destination's region and its slots, each checked in reach of the robot that sets a
    material down there (a LayoutError if none is), and the stand the youBot unloads there from
    (a carried class's destination other than the pool: the nearer stand)."""
    from cell_layout.loader_reach import loader_place_slots
    ox, oy, oz = obstacle.position
    if abs(math.sin(2 * obstacle.yaw)) > 1e-9:
        raise LayoutError(f'destination {name} is turned {math.degrees(obstacle.yaw):.0f} deg: '
                          'a destination lies along the world axes')
    hx, hy = obstacle.size[0] / 2, obstacle.size[1] / 2
    if abs(math.cos(obstacle.yaw)) < 0.5:
        hx, hy = hy, hx
    top = oz + obstacle.size[2] / 2
    bound = [r for r in layout.rules.values() if r.destination == name]
    size = max(r.size for r in bound)
    routes = {r.route for r in bound}
    if len(routes) > 1:
        raise LayoutError(f'destination {name} is reached by both routes '
                          f'({", ".join(r.name for r in bound)}): give it one')
    if name == POOL:
        if routes != {'carry'}:
            raise LayoutError(f'{POOL} is the youBot\'s: its materials are carried there '
                              '(route: carry)')
        drops = tuple(d for st in layout.stands for d in st.drops)
        return Region(name, (ox, oy), (hx, hy), top, drops, drop=True), ''

    if routes == {'place'}:
        return Region(name, (ox, oy), (hx, hy), top, loader_place_slots(
            layout, name, slot_grid((ox, oy), (hx, hy), top, size, (ox, oy)), size)), ''
    stand = min((st for st in layout.stands if st.side == 0),
                key=lambda st: math.hypot(st.pose[0] - ox, st.pose[1] - oy))
    slots = slot_grid((ox, oy), (hx, hy), top, size, stand.pose[:2])
    # Each slot the arm sets the heaviest of its classes down on, holding it at rest (from the
    # stand, or from the base slid along its line abeam the slot).
    mass = max(r.mass for r in bound)
    reached = [p for p in slots if _youbot_reaches_from(
        stand, p + np.array([0.0, 0.0, size + 0.015]), layout.youbot_base_z, 0.0, mass, 0.05)]
    if not reached:
        light = mass > 0.0 and any(_youbot_reaches_from(
            stand, p + np.array([0.0, 0.0, size + 0.015]), layout.youbot_base_z, 0.0, 0.0, 0.05)
            for p in slots)
        raise LayoutError(f'destination {name} is out of the youBot arm\'s reach from its '
                          f'unload stands beside the pool' + (
                              f' holding {mass:g} kg at rest (it reaches it empty-handed)'
                              if light else ''))
    return Region(name, (ox, oy), (hx, hy), top, tuple(reached)), stand.name


# The largest material the youBot carries [m].
CARRIED_MAX_M = 0.06


def _check_capacity(layout: CellLayout) -> None:
    """Every destination has a slot for each material bound for it (the youBot makes as many
    trips as its load needs), every carried material fits the plate's slots, and the youBot's
    arm holds it at rest over one of them at least."""
    for name, rule in layout.rules.items():
        if rule.route == 'carry' and rule.size > CARRIED_MAX_M + 1e-9:
            raise LayoutError(f'{name} ({rule.size} m) is too large to be carried: the youBot '
                              f'carries materials of at most {CARRIED_MAX_M} m')
        if rule.route == 'carry' and rule.mass > 0.0:
            _check_plate_load(layout, name, rule.size, rule.mass)
    for name, region in layout.regions.items():
        bound = sum(n for c, n in layout.manifest.items() if layout.destination(c) == name)
        if bound > len(region.slots):
            raise LayoutError(f'destination {name} has {len(region.slots)} slots in reach for '
                              f'{bound} materials')
