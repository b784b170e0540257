"""The youBot on a full ROS 2 Jazzy install: simulator with the youBot world, the arm's
kinematics node, and optionally a recorder.

    ros2 launch sim_bringup youbot.launch.py [real_time_factor:=1.0] [gui:=false]
        [record:=false] [bag_dir:=bags]

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
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from ros_common.dds import profile_environment


def generate_launch_description():
    return LaunchDescription([
        # The project's Fast DDS profile (ros_common/dds.py), unless one is chosen already.
        *[SetEnvironmentVariable(name, value)
          for name, value in profile_environment().items()],
        DeclareLaunchArgument('real_time_factor', default_value='1.0'),
        DeclareLaunchArgument('gui', default_value='false'),
        DeclareLaunchArgument('record', default_value='false'),
        DeclareLaunchArgument('bag_dir', default_value='bags'),
        Node(package='sim_bridge', executable='sim_node', output='screen',
             parameters=[{'world': 'package://world_description/worlds/youbot.yaml',
                          'real_time_factor': LaunchConfiguration('real_time_factor'),
                          'gui': LaunchConfiguration('gui')}]),
        Node(package='arm_kinematics', executable='kinematics_node', namespace='youbot',
             output='screen'),
        Node(package='recording', executable='recorder', output='screen',
             condition=IfCondition(LaunchConfiguration('record')),
             parameters=[{'output_dir': LaunchConfiguration('bag_dir')}]),
    ])
