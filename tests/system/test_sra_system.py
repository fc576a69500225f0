"""The soft arm in closed loop as real processes: sra_sim and pressure_controller over DDS."""

from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from std_msgs.msg import String

from inflarm_msgs_json import ControlTask, TrialReport, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from ros_harness import spin_until

pytestmark = pytest.mark.system
TARGET = np.array([0.100, 0.110, 0.670])


def test_pid_drives_the_simulated_arm_towards_the_target(node_processes, executor):
    # the simulator's stand-in ball_position (the camera path has its own test)
    node_processes.start('inflarm_hw', 'sra_sim',
                         parameters={'seed': 7, 'publish_ball_position': True})
    node_processes.start('inflarm_control', 'pressure_controller',
                         parameters={'trial_duration_s': 25.0})
    probe = rclpy.create_node('probe', context=executor.context)
    truth: list[np.ndarray] = []
    reports: list[TrialReport] = []
    probe.create_subscription(
        PointStamped, 'end_point_truth',
        lambda m: truth.append(np.array([m.point.x, m.point.y, m.point.z])), SENSOR_QOS)
    probe.create_subscription(
        String, 'trial_report', lambda m: reports.append(decode(m.data)), RELIABLE_QOS)
    task_pub = probe.create_publisher(String, 'control_task', RELIABLE_QOS)
    executor.add_node(probe)
    assert spin_until(executor, lambda: task_pub.get_subscription_count() == 1 and truth,
                      timeout_s=20.0), node_processes.output()
    start_distance = np.linalg.norm(truth[-1] - TARGET)
    # The controller needs a ball position before it accepts the task.
    assert node_processes.wait_for_output('ready: 5.0 Hz'), node_processes.output()
    spin_until(executor, lambda: False, timeout_s=1.0)

    task_pub.publish(to_string_msg(
        ControlTask(frame_id='sra_mount', target=tuple(TARGET), mode='pid', trial_id=0)))
    assert spin_until(executor, lambda: reports, timeout_s=45.0), node_processes.output()
    final_distance = np.linalg.norm(truth[-1] - TARGET)
    assert start_distance > 0.1
    # PID alone is slow (paper: no axis within 15 s): after the 25 s trial x and y are within
    # 3 mm, z, the extensible actuators' slow stretch, 43 mm short (measured; 163 mm at rest)
    assert final_distance < 0.4 * start_distance, (truth[-1], node_processes.output())
    assert reports[0].trial_index == 0
    # PID alone is slow (paper: >= 15 s): the trial's RMSE sits between zero and the initial
    # error on every axis.
    initial_error = np.abs(TARGET - truth[0])
    assert all(0.0 < e < i for e, i in zip(reports[0].rmse, initial_error, strict=True))
