"""Elastostatic inverse kinematics and PID + iterative learning pressure control."""
