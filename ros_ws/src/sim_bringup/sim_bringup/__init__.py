"""Bring-up of the simulator with its nodes, and demo checks."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
drive_check_main = lazy_main('sim_bringup.drive_check')
arm_move_main = lazy_main('sim_bringup.arm_move')
