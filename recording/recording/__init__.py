"""Recording runs to rosbag2 bags, replaying them, repairing and analysing them."""
