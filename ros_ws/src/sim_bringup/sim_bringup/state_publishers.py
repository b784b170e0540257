"""robot_state_publisher for each robot of a world, for launches with ``publish_link_tf:=false``
(no ROS launch here: the launch files turn these into Node actions).

Each gets the robot's URDF with its frame prefix applied, as sim_node publishes it on
``<ns>/robot_description``, and runs in the robot's namespace, where it reads ``joint_states``
and publishes the links' transforms on /tf and /tf_static with the names the simulator uses.
"""
from __future__ import annotations

from typing import Dict, List, Tuple, Union

from robot_description import with_frame_prefix
from world_description.resources import resolve_resource
from world_description.world_config import load_world

Parameters = Dict[str, Union[str, bool]]


def state_publishers(world: str, use_sim_time: bool = True) -> List[Tuple[str, Parameters]]:
    """(namespace, parameters) of one robot_state_publisher per robot of ``world``."""
    config = load_world(resolve_resource(world))
    base_dir = resolve_resource(world).parent
    out: List[Tuple[str, Parameters]] = []
    for robot in config.robots:
        urdf = resolve_resource(robot.urdf, base_dir).read_text()
        parameters: Parameters = {
            'robot_description': with_frame_prefix(urdf, robot.frame_prefix),
            'use_sim_time': use_sim_time}
        out.append((robot.namespace, parameters))
    return out
