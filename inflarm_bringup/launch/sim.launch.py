"""Both simulated arms (or both behind hw_bridge): the inflatable arm and the soft arm.

    ros2 launch inflarm_bringup sim.launch.py
        [backend:=sim|sim_mcu|hardware] [port:=DEVICE]
        [rviz:=true] [log_level:=debug]

The same nodes and parameters as ``inflarm-launch sim``
(inflarm_bringup.launch_description).
"""

from inflarm_bringup.launch_description import system_launch_description


def generate_launch_description():
    return system_launch_description('sim')
