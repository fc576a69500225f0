"""The smoke nodes in-process: parameter conventions and input handling through real topics."""

import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from inflarm_hw.nodes.demo_joint_publisher import DemoJointPublisher
from inflarm_hw.nodes.joint_state_monitor import JointStateMonitor
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from ros_harness import spin_until


def test_publisher_defaults_and_rejected_sets(executor):
    node = DemoJointPublisher(context=executor.context)
    executor.add_node(node)
    assert node.get_parameter('rate_hz').value == 50.0
    assert node.get_parameter('joint_names').value == ['joint_1', 'joint_2', 'joint_3']
    out_of_range = node.set_parameters([Parameter('rate_hz', value=0.0)])[0]
    assert not out_of_range.successful
    wrong_type = node.set_parameters([Parameter('amplitude_rad', value='big')])[0]
    assert not wrong_type.successful
    read_only = node.set_parameters([Parameter('joint_names', value=['x'])])[0]
    assert not read_only.successful
    assert node.get_parameter('rate_hz').value == 50.0


def test_publisher_publishes_named_joints_and_applies_a_new_rate(executor):
    node = DemoJointPublisher(
        context=executor.context,
        parameter_overrides=[Parameter('joint_names', value=['a', 'b']),
                             Parameter('amplitude_rad', value=0.25)])
    probe = rclpy.create_node('probe', context=executor.context)
    received: list[JointState] = []
    probe.create_subscription(JointState, 'joint_states', received.append, SENSOR_QOS)
    executor.add_node(node)
    executor.add_node(probe)
    assert spin_until(executor, lambda: len(received) >= 3)
    assert list(received[-1].name) == ['a', 'b']
    assert all(abs(p) <= 0.25 for msg in received for p in msg.position)

    assert node.set_parameters([Parameter('rate_hz', value=5.0)])[0].successful
    assert node.timer.timer_period_ns == 200_000_000


def test_monitor_rejects_malformed_joint_states_and_keeps_running(executor):
    monitor = JointStateMonitor(context=executor.context)
    source = rclpy.create_node('source', context=executor.context)
    pub = source.create_publisher(JointState, 'joint_states', SENSOR_QOS)
    executor.add_node(monitor)
    executor.add_node(source)
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1)

    pub.publish(JointState(name=['joint_1', 'joint_2'], position=[0.1]))
    pub.publish(JointState(name=['joint_1'], position=[float('nan')]))
    assert spin_until(executor, lambda: monitor.rejected == 2)
    pub.publish(JointState(name=['joint_1'], position=[0.3]))
    assert spin_until(executor, lambda: monitor.latest is not None)
    assert list(monitor.latest.position) == [0.3]
