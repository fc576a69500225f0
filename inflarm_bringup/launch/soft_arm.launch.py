"""The pneumatic soft arm: its robot, ball_tracker, path_planner, pressure_controller.

    ros2 launch inflarm_bringup soft_arm.launch.py
        [backend:=sim|sim_mcu|hardware] [port:=DEVICE]
        [rviz:=true] [log_level:=debug]

The same nodes and parameters as ``inflarm-launch soft_arm``
(inflarm_bringup.launch_description).
"""

from inflarm_bringup.launch_description import system_launch_description


def generate_launch_description():
    return system_launch_description('soft_arm')
