"""robot_description node: latched URDF from parameters, validated runtime changes."""

import pinocchio as pin
import pytest
import rclpy
from rclpy.parameter import Parameter
from std_msgs.msg import String

from inflarm_model.nodes.robot_description import RobotDescription
from inflarm_model.urdf import spring_stiffness_from_urdf
from inflarm_msgs_json.ros.qos import LATCHED_QOS
from ros_harness import spin_until


def subscribe(executor) -> list[String]:
    probe = rclpy.create_node('probe', context=executor.context)
    received: list[String] = []
    probe.create_subscription(String, 'robot_description', received.append, LATCHED_QOS)
    executor.add_node(probe)
    return received


def test_a_late_subscriber_gets_the_urdf_of_the_configured_arm(executor):
    node = RobotDescription(
        context=executor.context,
        parameter_overrides=[
            Parameter('arm.link_length_m', value=0.5),
            Parameter('arm.spring_stiffness', value=[150.0, 160.0, 170.0, 180.0]),
        ])
    executor.add_node(node)
    received = subscribe(executor)  # after the node published: latched delivery
    assert spin_until(executor, lambda: len(received) == 1)
    urdf = received[0].data
    assert spring_stiffness_from_urdf(urdf) == {
        'spring_1': 150.0, 'spring_2': 160.0, 'spring_3': 170.0, 'spring_4': 180.0}
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    q = pin.neutral(model)
    pin.framesForwardKinematics(model, data, q)
    tip = data.oMf[model.getFrameId('tip')].translation
    assert tip[0] == pytest.approx(2 * 0.5)  # stretched out: two links of 0.5 m along x


def test_stiffness_changes_republish_and_bad_values_are_rejected(executor):
    node = RobotDescription(context=executor.context)
    executor.add_node(node)
    received = subscribe(executor)
    assert spin_until(executor, lambda: len(received) == 1)

    rejected = [
        node.set_parameters([Parameter('arm.spring_stiffness', value=[100.0, 100.0, 100.0])]),
        node.set_parameters([Parameter('arm.spring_stiffness', value=[1.0, -1.0, 1.0, 1.0])]),
        node.set_parameters([Parameter('arm.link_length_m', value=0.7)]),  # read-only
    ]
    assert not any(result[0].successful for result in rejected)
    assert 'arm.spring_stiffness must be 4 positive finite numbers' in rejected[0][0].reason

    ok = node.set_parameters([Parameter('arm.spring_stiffness', value=[200.0] * 4)])
    assert ok[0].successful
    assert spin_until(executor, lambda: len(received) == 2)
    assert set(spring_stiffness_from_urdf(received[1].data).values()) == {200.0}


def test_an_inconsistent_geometry_fails_at_startup(ros_context):
    with pytest.raises(ValueError, match='arm.spring_offset_m'):
        RobotDescription(
            context=ros_context,
            parameter_overrides=[Parameter('arm.spring_offset_m', value=0.8)])
