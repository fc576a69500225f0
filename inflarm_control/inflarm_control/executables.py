"""The node executables of inflarm_control, as ``setup.py`` registers them (console scripts).

Each entry point owns SIGINT and SIGTERM before it imports its node module (rclpy, numpy and
Pinocchio take about a second), so a stop request during start-up is never lost: see
``inflarm_msgs_json.ros.signals``. The node classes live in ``nodes/``.
"""

from inflarm_msgs_json.ros.signals import node_entry

elastostatic_ik = node_entry('inflarm_control.nodes.elastostatic_ik')
pressure_controller = node_entry('inflarm_control.nodes.pressure_controller')
tip_path_demo = node_entry('inflarm_control.nodes.tip_path_demo')
trial_runner = node_entry('inflarm_control.nodes.trial_runner')
