"""PyBullet simulator for ROS 2: a ROS-free world core and a thin node around it."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
sim_node_main = lazy_main('sim_bridge.sim_node')
