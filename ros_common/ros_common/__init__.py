"""ROS glue shared by the project's nodes."""
