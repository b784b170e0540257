"""The simulator node's parameters: one table (names, defaults, ranges, descriptions) from
which ``sim_node`` declares them, and the checks across parameters that a range cannot say."""
from __future__ import annotations

from typing import Any, Dict

from ros_common.params import Param

DEFAULT_WORLD = 'package://world_description/worlds/mini_robot.yaml'


class SimConfigError(ValueError):
    """A parameter combination the simulator cannot run with."""


PARAMS = (
    Param('world', DEFAULT_WORLD, 'World YAML: a path or package://<pkg>/<path>'),
    Param('gui', False, 'Open the PyBullet GUI (needs a display)'),
    Param('time_step', 1.0 / 240.0, 'Fixed physics step [s]', 1e-4, 0.05),
    Param('real_time_factor', 1.0,
          'Pacing: simulated seconds per wall second; 0 runs as fast as possible', 0.0, 100.0),
    Param('synchronous', False, 'Lock-step: physics advances only on ~/step requests'),
    Param('state_publish_rate', 100.0,
          'Rate of joint_states and odom [Hz of simulated time]', 0.1, 10000.0),
    Param('clock_publish_rate', 0.0,
          'Rate of /clock [Hz of simulated time]; 0: after every physics step. Lock-step also '
          'publishes it at the end of every ~/step. Each message costs every node with '
          'use_sim_time about a millisecond of CPU in rclpy; a node that plans ahead in real '
          'time needs a fresh clock', 0.0, 10000.0),
    Param('max_speed', 0.2, 'Linear speed limit (each of x, y) of bases whose world entry sets '
          'none [m/s]', 1e-3, 10.0),
    Param('max_turn', 0.2, 'Turn rate limit of bases whose world entry sets none [rad/s]',
          1e-3, 20.0),
    # diff_drive_controller's names; the world file's max_accel and max_turn_accel win.
    Param('linear.x.max_acceleration', 0.0,
          'Acceleration limit of the applied command (each of linear x and y) of bases whose '
          'world entry sets none [m/s^2]; 0: no limit', 0.0, 100.0),
    Param('angular.z.max_acceleration', 0.0,
          'Angular acceleration limit of the applied command of bases whose world entry sets '
          'none [rad/s^2]; 0: no limit', 0.0, 200.0),
    Param('cmd_vel_timeout', 0.5,
          'Stop a base when its last cmd_vel is older than this [s of simulated time]',
          1e-3, 60.0),
    Param('use_stamped_vel', False,
          'Take geometry_msgs/TwistStamped on cmd_vel instead of Twist'),
    Param('rtf_log_period', 10.0,
          'Log the achieved real-time factor every this many wall seconds; 0 disables',
          0.0, 3600.0),
    # Behind schedule, the steps of a burst take no commands: a long burst leaves a base
    # driving on a stale cmd_vel for its length.
    Param('max_steps_per_tick', 8, 'Most physics steps run between two rounds of callbacks',
          1, 10000),
    Param('step_chunk', 240,
          'Lock-step: a ~/step request of more steps is run this many at a time, the node '
          'serving its other callbacks (commands, services) between chunks, and answered after '
          'the last', 1, 100000),
    Param('belt_speed', -1.0, "Conveyor belt speed [m/s]; -1 keeps the world file's; settable "
          'while running', -1.0, 2.0, read_only=False),
    Param('scenario_seed', -1, "Seed of the materials' order and spacing; -1 keeps the world "
          "file's", -1, 2**31 - 1),
    Param('materials_publish_rate', 10.0,
          "Rate of the materials' ground truth on /cell/materials [Hz of simulated time]",
          0.1, 1000.0),
    Param('publish_link_tf', True,
          "Publish the robots' link transforms on /tf and /tf_static (off: "
          'robot_state_publisher does it from joint_states and robot_description); odom -> '
          "base_link and the world's anchors are published either way"),
    Param('camera_reliability', 'reliable',
          'QoS reliability of camera images and camera_info: reliable (the system default, '
          "which RViz and rqt ask for; best-effort readers match it too) or best_effort",
          choices=('reliable', 'best_effort')),
    Param('jpeg_quality', 90, 'JPEG quality of <camera>/image_raw/compressed', 1, 100),
)


def check_params(p: Dict[str, Any]) -> None:
    """What one parameter's range cannot say; raises SimConfigError."""
    if p['state_publish_rate'] * p['time_step'] > 1.0 + 1e-9:
        raise SimConfigError(
            f'state_publish_rate {p["state_publish_rate"]} Hz exceeds the physics rate '
            f'{1.0 / p["time_step"]:.1f} Hz (1/time_step)')
