"""The node executables of inflarm_planning, as ``setup.py`` registers them (console scripts).

Each entry point owns SIGINT and SIGTERM before it imports its node module (rclpy, numpy and
numba take about a second), so a stop request during start-up is never lost: see
``inflarm_msgs_json.ros.signals``. The node classes live in ``nodes/``.
"""

from inflarm_msgs_json.ros.signals import node_entry

path_planner = node_entry('inflarm_planning.nodes.path_planner')
