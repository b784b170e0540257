"""The youBot on a full ROS 2 Jazzy install: simulator with the youBot world, the arm's
kinematics node, and optionally a recorder.

    ros2 launch sim_bringup youbot.launch.py [real_time_factor:=1.0] [gui:=false]
        [record:=false] [bag_dir:=bags] [publish_link_tf:=true]

Then drive it:
    ros2 run teleop teleop --ros-args -r __ns:=/youbot -p holonomic:=true
    ros2 topic pub --once /youbot/arm_controller/joint_trajectory \\
        trajectory_msgs/msg/JointTrajectory "{joint_names: [arm_joint_1, arm_joint_2,
        arm_joint_3, arm_joint_4, arm_joint_5], points: [{positions: [0.5, 0.6, 0.9, 0.8, 0.0],
        time_from_start: {sec: 2}}]}"
    ros2 service call /youbot/solve_ik sim_interfaces/srv/SolveIK "{execute: true, target:
        {header: {frame_id: base_link}, pose: {position: {x: 0.45, y: 0.0, z: 0.05},
        orientation: {y: 1.0, w: 0.0}}}}"
(ros2 launch is not installable from the package index; docs/nodes.md shows the same nodes
started one by one.)
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from ros_common.dds import profile_environment
from sim_bringup.state_publishers import state_publishers

WORLD = 'package://world_description/worlds/youbot.yaml'


def _state_publishers(context):
    # publish_link_tf:=false: robot_state_publisher publishes the links from joint_states.
    if context.launch_configurations['publish_link_tf'].lower() == 'true':
        return []
    return [Node(package='robot_state_publisher', executable='robot_state_publisher',
                 namespace=ns, output='screen', parameters=[params])
            for ns, params in state_publishers(WORLD)]


def generate_launch_description():
    return LaunchDescription([
        # The project's Fast DDS profile (ros_common/dds.py), unless one is chosen already.
        *[SetEnvironmentVariable(name, value)
          for name, value in profile_environment().items()],
        DeclareLaunchArgument('real_time_factor', default_value='1.0'),
        DeclareLaunchArgument('gui', default_value='false'),
        DeclareLaunchArgument('record', default_value='false'),
        DeclareLaunchArgument('bag_dir', default_value='bags'),
        DeclareLaunchArgument('publish_link_tf', default_value='true'),
        Node(package='sim_bridge', executable='sim_node', output='screen',
             parameters=[{'world': WORLD,
                          'real_time_factor': LaunchConfiguration('real_time_factor'),
                          'gui': LaunchConfiguration('gui'),
                          'publish_link_tf': LaunchConfiguration('publish_link_tf')}]),
        OpaqueFunction(function=_state_publishers),
        Node(package='arm_kinematics', executable='kinematics_node', namespace='youbot',
             output='screen'),
        Node(package='recording', executable='recorder', output='screen',
             condition=IfCondition(LaunchConfiguration('record')),
             parameters=[{'output_dir': LaunchConfiguration('bag_dir')}]),
    ])
