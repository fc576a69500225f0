"""Elastostatic load and pose estimation for the inflatable-link arm."""
