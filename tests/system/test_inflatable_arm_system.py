"""The inflatable arm chain as real processes: arm_sim -> load_estimator -> elastostatic_ik."""

from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy

from inflarm_msgs_json.ros.qos import COMMAND_QOS, SENSOR_QOS
from ros_harness import BaseFrameForces, spin_until

pytestmark = pytest.mark.system
LOAD = np.array([0.0, 10.0, -15.0])
ARM_CONFIG = ('inflarm_model', 'inflatable_arm.yaml')


def test_the_load_is_estimated_and_the_target_reached_in_closed_loop(node_processes, executor):
    from ament_index_python.packages import get_package_share_directory
    arm_yaml = f'{get_package_share_directory(ARM_CONFIG[0])}/config/{ARM_CONFIG[1]}'
    for package, node in (('inflarm_hw', 'arm_sim'), ('inflarm_estimation', 'load_estimator'),
                          ('inflarm_control', 'elastostatic_ik')):
        node_processes.start(package, node, '--params-file', arm_yaml,
                             parameters={'seed': 7} if node == 'arm_sim' else None)
    probe = rclpy.create_node('probe', context=executor.context)
    wrenches = BaseFrameForces(probe)
    tips: list[np.ndarray] = []
    probe.create_subscription(
        PointStamped, 'tip_position_truth',
        lambda m: tips.append(np.array([m.point.x, m.point.y, m.point.z])), SENSOR_QOS)
    target_pub = probe.create_publisher(PointStamped, 'tip_target', COMMAND_QOS)
    executor.add_node(probe)

    # arm_sim -> load_estimator: the simulated load, recovered within the sensor noise
    assert spin_until(executor, lambda: len(wrenches) >= 50, timeout_s=20.0), \
        node_processes.output()
    mean_force = np.mean([f for _, f in wrenches.forces[-50:]], axis=0)
    np.testing.assert_allclose(mean_force, LOAD, atol=0.3)

    # elastostatic_ik + arm_sim, with the estimated load: the true tip reaches the target
    assert spin_until(executor, lambda: target_pub.get_subscription_count() >= 1)
    target = np.array([0.8, 0.2, 0.1])
    msg = PointStamped()
    msg.header.frame_id = 'base_link'
    msg.point.x, msg.point.y, msg.point.z = target.tolist()
    target_pub.publish(msg)
    assert spin_until(executor, lambda: np.linalg.norm(tips[-1] - target) < 1e-3,
                      timeout_s=20.0), (tips[-1], node_processes.output())
