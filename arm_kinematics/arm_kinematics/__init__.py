"""Arm kinematics node (the MDH kinematics core is in controllers)."""
