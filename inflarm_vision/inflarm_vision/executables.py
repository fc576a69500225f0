"""The node executables of inflarm_vision, as ``setup.py`` registers them (console scripts).

Each entry point owns SIGINT and SIGTERM before it imports its node module (rclpy, numpy and
OpenCV take about a second), so a stop request during start-up is never lost: see
``inflarm_msgs_json.ros.signals``. The node classes live in ``nodes/``.
"""

from inflarm_msgs_json.ros.signals import node_entry

ball_tracker = node_entry('inflarm_vision.nodes.ball_tracker')
camera_driver = node_entry('inflarm_vision.nodes.camera_driver')
