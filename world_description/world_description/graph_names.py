"""The ROS names a world's graph makes: every node, topic, service and action that the simulator,
the arms' IK servers, the vision node and the pipeline coordinator create for its robots and
cameras (as the trial graph and the launch files start them), checked once when the world is
read. Each must be a name ROS takes (rmw's rules for a fully qualified name, and its length
limits), and no name may be made for two different things: a youBot whose namespace and grip
service give ``/sim_node/reset`` would take the simulator's own reset, and two grip services
that come out as one name would each answer for the other's robot.

``tests/graph`` holds this table to the names a running graph has.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Iterator, List, Optional, Tuple

from world_description.ros_names import name_problem
from world_description.world_schema import WorldConfig

# The nodes of the graph and what each makes under its own name (``~/``). Every node offers
# rclpy's parameter services (and, in Jazzy, its type description service).
SIM_NODE, VISION_NODE, COORDINATOR_NODE = 'sim_node', 'vision_node', 'coordinator_node'
KINEMATICS_NODE = 'kinematics_node'            # in each arm's robot's namespace
NODE_SERVICES = ('describe_parameters', 'get_parameter_types', 'get_parameters',
                 'get_type_description', 'list_parameters', 'set_parameters',
                 'set_parameters_atomically')
SIM_SERVICES = ('reset', 'pause', 'resume', 'step', 'step_simulation',
                # simulation_interfaces
                'get_simulator_features', 'get_simulation_state', 'set_simulation_state',
                'reset_simulation', 'get_current_world', 'get_available_worlds', 'load_world',
                'unload_world', 'get_entities', 'get_entities_states', 'get_entity_state',
                'set_entity_state', 'get_entity_info', 'set_entity_info', 'get_entity_bounds',
                'spawn_entity', 'spawn_entities', 'delete_entity', 'get_spawnables',
                'get_named_poses', 'get_named_pose_bounds')
SIM_ACTIONS = ('simulate_steps',)
SIM_TOPICS = ('joint_limits', 'base_clearance')
COORDINATOR_TOPICS = ('state', 'events')
# Names the graph makes at the top level (ROS's own, the simulator's, the vision node's).
GLOBAL_TOPICS = ('/rosout', '/parameter_events', '/clock', '/tf', '/tf_static',
                 '/diagnostics', '/cell/materials', '/detections', '/debug_image')
# The conveyor drive's encoder, where the world gives the cell one (sim_bridge.belt_encoder).
BELT_ENCODER_TOPIC = '/conveyor/joint_states'
# What a robot has under its namespace, by what it is.
ROBOT_TOPICS = ('joint_states', 'robot_description')
BASE_TOPICS = ('odom',)                          # a mobile base (no fixed base)
DRIVE_TOPICS = ('cmd_vel', 'cmd_vel_out')        # a driven base
CONTROLLER_TOPICS = ('joint_trajectory', 'controller_state')
CONTROLLER_ACTIONS = ('follow_joint_trajectory',)
GRIP_TOPICS = ('holding', 'state')               # under the grip service's name
CAMERA_TOPICS = ('image_raw', 'image_raw/compressed', 'camera_info')
KINEMATICS_TOPICS = ('end_effector_pose', 'ik_status', 'goal_pose')
KINEMATICS_SERVICES = ('solve_ik',)
# What an action server makes of its name (rclpy, rcl_action).
ACTION_SERVICES = ('_action/send_goal', '_action/cancel_goal', '_action/get_result')
ACTION_TOPICS = ('_action/feedback', '_action/status')


@dataclass(frozen=True)
class GraphName:
    name: str               # fully qualified
    kind: str               # node, topic or service
    owner: str              # what makes it, in words


def _under(namespace: str, name: str) -> str:
    return '/' + '/'.join(p for p in (namespace.strip('/'), name.strip('/')) if p)


def _action(name: str, owner: str) -> Iterator[GraphName]:
    for leaf in ACTION_SERVICES:
        yield GraphName(f'{name}/{leaf}', 'service', owner)
    for leaf in ACTION_TOPICS:
        yield GraphName(f'{name}/{leaf}', 'topic', owner)


def _node(namespace: str, node: str, owner: str) -> Iterator[GraphName]:
    full = _under(namespace, node)
    yield GraphName(full, 'node', owner)
    for leaf in NODE_SERVICES:
        yield GraphName(f'{full}/{leaf}', 'service', owner)


def graph_names(world: WorldConfig) -> List[GraphName]:
    """Every name the graph makes for ``world``."""
    out: List[GraphName] = [GraphName(t, 'topic', 'ROS and the simulator')
                            for t in GLOBAL_TOPICS]
    sim = f'the simulator ({SIM_NODE})'
    out += _node('', SIM_NODE, sim)
    out += [GraphName(_under(SIM_NODE, s), 'service', sim) for s in SIM_SERVICES]
    out += [GraphName(_under(SIM_NODE, t), 'topic', sim) for t in SIM_TOPICS]
    for a in SIM_ACTIONS:
        out += _action(_under(SIM_NODE, a), sim)
    if world.conveyor is not None and world.conveyor.encoder is not None:
        out.append(GraphName(BELT_ENCODER_TOPIC, 'topic', "the conveyor's encoder"))
    out += _node('', VISION_NODE, 'the vision node')
    out += _node('', COORDINATOR_NODE, 'the coordinator')
    out += [GraphName(_under(COORDINATOR_NODE, t), 'topic', 'the coordinator')
            for t in COORDINATOR_TOPICS]
    for robot in world.robots:
        ns, who = robot.namespace, f'robot {robot.name}'
        out += [GraphName(_under(ns, t), 'topic', who) for t in ROBOT_TOPICS]
        if not robot.fixed_base:
            out += [GraphName(_under(ns, t), 'topic', f'{who}\'s base') for t in BASE_TOPICS]
        if robot.drive is not None:
            out += [GraphName(_under(ns, t), 'topic', f'{who}\'s drive') for t in DRIVE_TOPICS]
        for c in robot.controllers:
            owner = f'{who}\'s controller {c.name}'
            out += [GraphName(_under(ns, f'{c.name}/{t}'), 'topic', owner)
                    for t in CONTROLLER_TOPICS]
            for a in CONTROLLER_ACTIONS:
                out += _action(_under(ns, f'{c.name}/{a}'), owner)
        if robot.suction is not None:
            grip, owner = _under(ns, robot.suction.service), f'{who}\'s grip service'
            out += [GraphName(grip, 'service', owner)]
            out += [GraphName(f'{grip}/{t}', 'topic', owner) for t in GRIP_TOPICS]
        if robot.controllers:          # (an arm: the pipeline runs its IK server)
            owner = f'{who}\'s IK server'
            out += _node(ns, KINEMATICS_NODE, owner)
            out += [GraphName(_under(ns, t), 'topic', owner) for t in KINEMATICS_TOPICS]
            out += [GraphName(_under(ns, s), 'service', owner) for s in KINEMATICS_SERVICES]
    spaces = {r.name: r.namespace for r in world.robots}
    for i, cam in enumerate(world.cameras):
        ns = spaces.get(cam.robot, '') if cam.robot else ''
        out += [GraphName(_under(ns, f'{cam.name}/{t}'), 'topic', f'cameras[{i}] ({cam.name})')
                for t in CAMERA_TOPICS]
    return out


def graph_problem(world: WorldConfig) -> Optional[str]:
    """The first name of ``world``'s graph that ROS would refuse, or that two different things
    make; None if there is none."""
    seen: Dict[Tuple[str, str], str] = {}
    for n in graph_names(world):
        problem = name_problem(n.name)
        if problem:
            return f'{n.owner} makes the {n.kind} {n.name[:80]}, which {problem}'
        held = seen.setdefault((n.kind, n.name), n.owner)
        if held != n.owner:
            return (f'{n.owner} makes the {n.kind} {n.name}, which {held} makes too: give '
                    'one of them another namespace or name')
    return None
