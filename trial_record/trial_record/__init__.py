"""A trial's record: its events, its score, its result file (no ROS)."""
