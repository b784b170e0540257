"""PyBullet simulator for ROS 2: a ROS-free world core and a thin node around it."""
