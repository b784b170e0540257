"""Teleoperation of a mobile base: the mini robot report's keys and timed scripts
(teleop_core, no ROS), and the teleop node."""
