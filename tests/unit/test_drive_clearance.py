"""Every drive the youBot makes between home and its stands keeps its footprint clear of the
world's obstacles, followed as the transport follows it (its path follower on a kinematic
base). A trip whose first stand was the right one drove the way laid out for the left stand and
turned round past the pool's north-west corner: its corner swept 2.7 cm into the wall, the base
stopped dead, the plate's materials slid 6 cm, and the youBot's grasp of one missed twice."""
import math
from pathlib import Path

import numpy as np
import pytest

from cell_layout.world_layout import (
    YOUBOT_HALF_LENGTH_M,
    YOUBOT_HALF_WIDTH_M,
    _footprint,
    _overlap,
    layout_from_world,
)
from controllers.bezier import BezierPath, key_poses_between
from controllers.path_follower import PathFollower, PDGains, TurnLimits, simulate_kinematic
from coordinator.pipeline import Settings
from world_description.resources import resolve_resource
from world_description.world_config import load_world

WORLDS = Path(resolve_resource('package://world_description/worlds/pipeline_cell.yaml')).parent
CLEARANCE_M = 0.01


def _clearance(pose, boxes) -> float:
    """How far the base's footprint at ``pose`` may grow before it meets an obstacle [m]."""
    lo, hi = -0.3, 0.3
    for _ in range(24):
        mid = (lo + hi) / 2
        grown = ((pose[0], pose[1]), pose[2], (YOUBOT_HALF_LENGTH_M + mid,
                                               YOUBOT_HALF_WIDTH_M + mid))
        if any(_overlap(grown, b) for b in boxes):
            hi = mid
        else:
            lo = mid
    return lo


def _drives(layout):
    """(name, start, via, goal) of every drive the transport makes."""
    home = layout.youbot_home
    for st in layout.stands:
        yield f'home -> {st.name}', home, layout.way_out(st.name), st.pose
        yield f'{st.name} -> home', st.pose, layout.via_back, home
        for other in layout.stands:
            if other is not st:
                yield f'{st.name} -> {other.name}', st.pose, layout.via_turn, other.pose


@pytest.mark.slow
@pytest.mark.parametrize('name', ['pipeline_cell', 'cell_two_trips', 'cell_four_classes',
                                  'cell_mixed_sizes'])
def test_every_drive_keeps_the_base_clear_of_the_obstacles(name):
    world = load_world(str(WORLDS / f'{name}.yaml'))
    layout, s = layout_from_world(world), Settings()
    boxes = [_footprint(o) for o in world.obstacles if o.collision
             and o.position[2] + (o.size[2] if o.shape == 'box' else o.size[-1]) / 2 > 0.01]
    for drive, start, via, goal in _drives(layout):
        path = BezierPath(key_poses_between(start, goal, via))
        follower = PathFollower(path, 0.0, s.drive_speed, s.drive_accel,
                                PDGains(max_speed=s.base_max_speed, max_turn=s.base_max_turn),
                                turn=TurnLimits(s.drive_turn, s.drive_turn_accel))
        poses, statuses = simulate_kinematic(follower, start, dt=0.02, lag=0.05)
        assert statuses[-1].finished, drive
        worst = min(_clearance(p, boxes) for p in poses[::2])
        assert worst >= CLEARANCE_M, f'{drive}: {worst * 100:.1f} cm'


def test_the_way_out_to_a_stand_facing_the_other_way_turns_where_the_stands_turn():
    layout = layout_from_world(load_world(str(WORLDS / 'pipeline_cell.yaml')))
    left, right = layout.stand('pool_left'), layout.stand('pool_right')
    assert abs(math.remainder(left.pose[2] - right.pose[2], 2 * math.pi)) == pytest.approx(
        math.pi)
    assert layout.way_out('pool_left') == layout.via_out
    assert layout.way_out('pool_right') == layout.via_turn
    assert np.allclose(layout.via_out[0][2], left.pose[2])
