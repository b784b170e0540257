"""Recording runs to rosbag2 bags, replaying them, repairing and analysing them."""

from ros_common.early_stop import lazy_main

# The executables (setup.py): each imports its module once Ctrl-C and SIGTERM are handled.
recorder_main = lazy_main('recording.recorder')
replay_main = lazy_main('recording.replay')
