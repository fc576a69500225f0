"""The inflatable-link arm: its robot, robot_description, load_estimator, elastostatic_ik.

    ros2 launch inflarm_bringup inflatable_arm.launch.py
        [backend:=sim|sim_mcu|hardware] [port:=DEVICE]
        [rviz:=true] [log_level:=debug]

The same nodes and parameters as ``inflarm-launch inflatable_arm``
(inflarm_bringup.launch_description).
"""

from inflarm_bringup.launch_description import system_launch_description


def generate_launch_description():
    return system_launch_description('inflatable_arm')
