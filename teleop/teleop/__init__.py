"""Teleoperation of a mobile base: the mini robot report's keys and timed scripts
(teleop_core, no ROS), and the teleop node."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
teleop_main = lazy_main('teleop.teleop_node')
control_panel_main = lazy_main('teleop.control_panel')
