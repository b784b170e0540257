"""The pipeline coordinator: state machine core, node, results and trial runner."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
coordinator_node_main = lazy_main('coordinator.coordinator_node')
