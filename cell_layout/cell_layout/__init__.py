"""The pipeline cell as its world file and robot models describe it (no ROS)."""
