"""A Foxglove live bridge for the running graph (``live_view``)."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
live_view_main = lazy_main('live_view.live_view_node')
