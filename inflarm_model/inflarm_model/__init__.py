"""Kinematics and physics of the inflatable-link arm and the pneumatic soft arm."""
