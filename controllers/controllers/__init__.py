"""Robot base kinematics, command safety and teleop (ROS-free cores plus thin nodes)."""
