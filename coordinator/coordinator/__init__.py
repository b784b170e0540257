"""The pipeline coordinator: the cell's controller (its two machines, the layout and reach),
the node that runs it during a trial, and the trial's scored result."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
coordinator_node_main = lazy_main('coordinator.coordinator_node')
