"""The pipeline paper's run on a full ROS 2 Jazzy install: simulator with the cell world, the
vision node, the two arms' kinematics nodes and the coordinator, optionally recorded.

    ros2 launch sim_bringup pipeline.launch.py [synchronous:=true] [scenario_seed:=5]
        [belt_speed:=0.12] [real_time_factor:=1.0] [record:=false] [bag_dir:=bags]

The result: `ros2 topic echo /coordinator_node/state` (latched; the result JSON at the end)
and `/coordinator_node/events`. (ros2 launch is not installable from the package index; here
`run_trials --seeds 5` starts the same processes, and the README shows them one by one.)
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    sync = ParameterValue(LaunchConfiguration('synchronous'), value_type=bool)
    belt = ParameterValue(LaunchConfiguration('belt_speed'), value_type=float)
    seed = ParameterValue(LaunchConfiguration('scenario_seed'), value_type=int)
    sim_time = {'use_sim_time': True}
    return LaunchDescription([
        DeclareLaunchArgument('synchronous', default_value='true'),
        DeclareLaunchArgument('scenario_seed', default_value='0'),
        DeclareLaunchArgument('belt_speed', default_value='0.12'),
        DeclareLaunchArgument('real_time_factor', default_value='1.0'),
        DeclareLaunchArgument('record', default_value='false'),
        DeclareLaunchArgument('bag_dir', default_value='bags'),
        Node(package='sim_bridge', executable='sim_node', output='screen',
             parameters=[{'world': 'package://world_description/worlds/pipeline_cell.yaml',
                          'synchronous': sync, 'state_publish_rate': 30.0,
                          # Lock-step: /clock at the control rate (each costs every node with
                          # sim time about a millisecond); real time: every step, fresh.
                          'clock_publish_rate': ParameterValue(PythonExpression([
                              "30.0 if '", LaunchConfiguration('synchronous'),
                              "'.lower() == 'true' else 0.0"]), value_type=float),
                          'scenario_seed': seed, 'belt_speed': belt,
                          'real_time_factor': LaunchConfiguration('real_time_factor')}]),
        Node(package='perception', executable='vision_node', output='screen',
             parameters=[sim_time],
             remappings=[('image_raw', '/belt_camera/image_raw'),
                         ('camera_info', '/belt_camera/camera_info')]),
        Node(package='arm_kinematics', executable='kinematics_node', namespace='zu12',
             output='screen', parameters=[{**sim_time, 'arm': 'zu12'}]),
        Node(package='arm_kinematics', executable='kinematics_node', namespace='youbot',
             output='screen', parameters=[{**sim_time, 'arm': 'youbot'}]),
        Node(package='coordinator', executable='coordinator_node', output='screen',
             parameters=[{**sim_time, 'synchronous': sync, 'belt_speed': belt,
                          'scenario_seed': seed}]),
        Node(package='recording', executable='recorder', output='screen',
             condition=IfCondition(LaunchConfiguration('record')),
             parameters=[{**sim_time, 'output_dir': LaunchConfiguration('bag_dir'),
                          'exclude': ['/belt_camera/image_raw', '/debug_image']}]),
    ])
