"""The node executables of inflarm_bringup, as ``setup.py`` registers them (console scripts).

Each entry point owns SIGINT and SIGTERM before it imports its node module (rclpy, numpy, viser
and Pinocchio take about a second), so a stop request during start-up is never lost: see
``inflarm_msgs_json.ros.signals``. The node classes live in ``nodes/``.
"""

from inflarm_msgs_json.ros.signals import node_entry

live_view = node_entry('inflarm_bringup.nodes.live_view')
