"""The smoke system as real processes over real DDS, and the launcher that starts it."""

import os
import pathlib
import subprocess

import pytest
import rclpy
from sensor_msgs.msg import JointState

from inflarm_msgs_json.ros.qos import SENSOR_QOS
from ros_harness import spin_until

pytestmark = pytest.mark.system
REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_joint_states_flow_between_processes(node_processes, executor):
    node_processes.start('inflarm_hw', 'demo_joint_publisher', parameters={'rate_hz': 20.0})
    node_processes.start('inflarm_hw', 'joint_state_monitor',
                         parameters={'report_period_s': 0.5})
    probe = rclpy.create_node('probe', context=executor.context)
    received: list[JointState] = []
    probe.create_subscription(JointState, 'joint_states', received.append, SENSOR_QOS)
    executor.add_node(probe)

    assert spin_until(executor, lambda: len(received) >= 5, timeout_s=15.0), \
        node_processes.output()
    assert list(received[-1].name) == ['joint_1', 'joint_2', 'joint_3']
    # The monitor process received them too, over DDS from the other process.
    assert node_processes.wait_for_output('joint_states at'), node_processes.output()


def test_launcher_runs_the_smoke_system_and_stops_it_cleanly(domain_id):
    result = subprocess.run(
        [REPO_ROOT / 'scripts' / 'launch', 'smoke', '--duration', '4'],
        capture_output=True, text=True, timeout=90,
        env={**os.environ, 'ROS_DOMAIN_ID': str(domain_id)})
    assert result.returncode == 0, result.stdout + result.stderr
    assert '[demo_joint_publisher]' in result.stdout
    assert '[joint_state_monitor]' in result.stdout
    assert 'joint_states at' in result.stdout
