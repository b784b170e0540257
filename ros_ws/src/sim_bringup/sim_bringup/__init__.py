"""Bring-up of the simulator with its nodes, and demo checks."""
