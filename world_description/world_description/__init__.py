"""The worlds and the pipeline cell (no ROS): the world files and their schema and validation,
``package://`` resources, and the cameras' geometry."""

# The world files this package installs, as a world parameter names them.
PIPELINE_CELL = 'package://world_description/worlds/pipeline_cell.yaml'
YOUBOT_WORLD = 'package://world_description/worlds/youbot.yaml'
MINI_ROBOT_WORLD = 'package://world_description/worlds/mini_robot.yaml'
