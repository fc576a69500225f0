"""The node executables of inflarm_hw, as ``setup.py`` registers them (console scripts).

Each entry point owns SIGINT and SIGTERM before it imports its node module (rclpy, numpy and
Pinocchio take about a second), so a stop request during start-up is never lost: see
``inflarm_msgs_json.ros.signals``. The node classes live in ``nodes/``.
"""

from inflarm_msgs_json.ros.signals import node_entry

arm_sim = node_entry('inflarm_hw.nodes.arm_sim')
bag_player = node_entry('inflarm_hw.nodes.bag_player')
bag_recorder = node_entry('inflarm_hw.nodes.bag_recorder')
demo_joint_publisher = node_entry('inflarm_hw.nodes.demo_joint_publisher')
hw_bridge = node_entry('inflarm_hw.nodes.hw_bridge')
joint_state_monitor = node_entry('inflarm_hw.nodes.joint_state_monitor')
sim_mcu = node_entry('inflarm_hw.nodes.sim_mcu')
sra_sim = node_entry('inflarm_hw.nodes.sra_sim')
