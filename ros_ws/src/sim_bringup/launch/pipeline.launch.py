"""The pipeline paper's run on a full ROS 2 Jazzy install: simulator with the cell world, the
vision node, the two arms' kinematics nodes and the coordinator, optionally recorded.

    ros2 launch sim_bringup pipeline.launch.py [synchronous:=true] [scenario_seed:=5]
        [belt_speed:=0.12] [real_time_factor:=1.0] [record:=false] [bag_dir:=bags]
        [publish_link_tf:=true]

The processes and their parameters are the trial runner's (studies/trial_graph.py): this file
only turns them into launch_ros Node actions. The launch ends when the run ends: every node is
stopped once the coordinator exits, and the launch's exit code is 0 for a completed run, 1
otherwise. The result: the coordinator's last log line, `ros2 topic echo
/coordinator_node/state` while it runs (the result JSON at the end) and
`/coordinator_node/events`. A recorded run's bag keeps what ran: `run_trials --rerun BAG` runs
it again, `storyboard BAG` draws it.
(ros2 launch is not installable from the package index; there `run_trials --seeds 5` starts
the same processes, and `run_trials --show-graph` prints them.)
"""
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch_ros.actions import Node

from ros_common.dds import profile_environment
from sim_bringup.state_publishers import state_publishers
from studies.recorded import bag_metadata
from studies.trial_graph import TIME_STEP, pipeline_graph
from studies.trial_process import scenario
from trial_record.result import code_version
from world_description import PIPELINE_CELL


class RunFailed(RuntimeError):
    """The run did not complete: the launch ends with exit code 1."""


def _run_ended(event, context):
    """The coordinator exited: the run is over, and so is the launch."""
    if context.is_shutdown:             # (stopped by Ctrl-C: everything ends anyway)
        return []
    if event.returncode != 0:
        # (launch returns 1 only for an exception; it logs this one and shuts down.)
        raise RunFailed(f'the run did not complete (coordinator exit code {event.returncode}; '
                        'its log says why)')
    return [LogInfo(msg='the run completed: stopping the nodes'),
            EmitEvent(event=Shutdown(reason='the run completed'))]


def _nodes(context):
    def arg(name):
        return context.launch_configurations[name]

    synchronous = arg('synchronous').lower() == 'true'
    seed, belt, record = (int(arg('scenario_seed')), float(arg('belt_speed')),
                          arg('record').lower() == 'true')
    # A recorded run keeps what ran in its bag, as a trial runner's does (studies.recorded):
    # run_trials --rerun BAG runs it again in lock-step.
    metadata = (bag_metadata(0, seed, belt, code_version(), scenario(PIPELINE_CELL, TIME_STEP))
                if record else None)
    graph = pipeline_graph(
        seed, belt, synchronous=synchronous,
        real_time_factor=None if synchronous else float(arg('real_time_factor')),
        record_dir=arg('bag_dir') if record else None, bag_name=None, bag_metadata=metadata)
    link_tf = arg('publish_link_tf').lower() == 'true'
    nodes = []
    for n in graph:
        parameters = dict(n.parameters)
        if n.executable == 'sim_node':
            parameters['publish_link_tf'] = link_tf
        nodes.append(Node(package=n.package, executable=n.executable, name=None,
                          namespace=n.namespace or None, output='screen',
                          parameters=[parameters], remappings=list(n.remappings)))
        if n.executable == 'coordinator_node':
            nodes.append(RegisterEventHandler(OnProcessExit(target_action=nodes[-1],
                                                            on_exit=_run_ended)))
    if not link_tf:
        # robot_state_publisher publishes the links from joint_states instead.
        world = next(n.parameters['world'] for n in graph if n.executable == 'sim_node')
        nodes += [Node(package='robot_state_publisher', executable='robot_state_publisher',
                       namespace=ns, output='screen', parameters=[params])
                  for ns, params in state_publishers(str(world))]
    return nodes


def generate_launch_description():
    return LaunchDescription([
        # The project's Fast DDS profile (ros_common/dds.py), unless one is chosen already.
        *[SetEnvironmentVariable(name, value)
          for name, value in profile_environment().items()],
        DeclareLaunchArgument('synchronous', default_value='true'),
        DeclareLaunchArgument('scenario_seed', default_value='0'),
        DeclareLaunchArgument('belt_speed', default_value='0.12'),
        DeclareLaunchArgument('real_time_factor', default_value='1.0'),
        DeclareLaunchArgument('record', default_value='false'),
        DeclareLaunchArgument('bag_dir', default_value='bags'),
        DeclareLaunchArgument('publish_link_tf', default_value='true'),
        OpaqueFunction(function=_nodes),
    ])
