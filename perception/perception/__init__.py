"""Camera-based perception. The vision node sorts the
pipeline cell's materials by colour."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
vision_node_main = lazy_main('perception.vision_node')
