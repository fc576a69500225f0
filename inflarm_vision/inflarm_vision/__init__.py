"""Yellow-ball tracking in camera images."""
