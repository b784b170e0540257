"""Arm kinematics node (the MDH kinematics core is in controllers)."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
kinematics_node_main = lazy_main('arm_kinematics.kinematics_node')
