"""Hardware bridges to motors and valves, and the simulated robots, camera and MCU."""
