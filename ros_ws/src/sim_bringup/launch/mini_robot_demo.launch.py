"""The demo on a full ROS 2 Jazzy install: simulator, recorder, scripted teleop, drive_check.

    ros2 launch sim_bringup mini_robot_demo.launch.py [real_time_factor:=1.0] [gui:=false]
        [bag_dir:=bags]

(ros2 launch is not installable from the package index, so `make demo` runs
scripts/demo.sh, which starts the same three nodes with the same parameters.)
"""
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from ros_common.dds import profile_environment

LEG = 'speed 0.5, forward 5s, speed 1.0, left 7.854s'
SQUARE = ', '.join([LEG] * 4) + ', stop'


def generate_launch_description():
    params = PathJoinSubstitution([FindPackageShare('sim_bringup'), 'config', 'sim.yaml'])
    check = Node(package='sim_bringup', executable='drive_check', output='screen',
                 parameters=[{'use_sim_time': True, 'script': SQUARE}],
                 remappings=[('cmd_vel', '/mini_robot/cmd_vel'), ('odom', '/mini_robot/odom'),
                             ('cmd_vel_out', '/mini_robot/cmd_vel_out')])
    return LaunchDescription([
        # The project's Fast DDS profile (ros_common/dds.py), unless one is chosen already.
        *[SetEnvironmentVariable(name, value)
          for name, value in profile_environment().items()],
        DeclareLaunchArgument('real_time_factor', default_value='1.0'),
        DeclareLaunchArgument('gui', default_value='false'),
        DeclareLaunchArgument('bag_dir', default_value='bags'),
        # The run is recorded: all topics, MCAP, a new bag directory each time.
        Node(package='recording', executable='recorder', output='screen',
             parameters=[{'output_dir': LaunchConfiguration('bag_dir')}]),
        Node(package='sim_bridge', executable='sim_node', output='screen',
             parameters=[params, {'real_time_factor': LaunchConfiguration('real_time_factor'),
                                  'gui': LaunchConfiguration('gui')}]),
        check,
        Node(package='teleop', executable='teleop', namespace='mini_robot',
             output='screen',
             parameters=[{'use_sim_time': True, 'script': SQUARE, 'publish_rate': 50.0,
                          'wait_for_subscriber': 30.0}]),
        RegisterEventHandler(OnProcessExit(target_action=check,
                                           on_exit=[EmitEvent(event=Shutdown())])),
    ])
