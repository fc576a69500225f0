"""A* path planning around cuboid obstacles for the pneumatic soft arm."""
