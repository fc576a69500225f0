"""The soft arm's loop closed through the camera as real processes over DDS: sra_sim renders
camera/image_raw, ball_tracker publishes ball_position, pressure_controller drives a trial to the
Fig 7 target on it. (Learning through the camera from PID alone takes minutes of simulated
trials; that runs in-process in tests/bringup/test_camera_loop.py.)"""

from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from std_msgs.msg import String

from inflarm_control.pid_ilc import PidIlcController, run_trials
from inflarm_hw.sra_plant import NOISE_FREE, SoftArmPlant
from inflarm_msgs_json import ControlTask, TrialReport, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from ros_harness import spin_until

pytestmark = pytest.mark.system
START = (0.0, 0.0, 0.604)
TARGET = np.array([0.100, 0.110, 0.670])
TRIAL_S = 10.0


def test_ball_position_from_the_camera_drives_a_trial_to_the_fig7_target(
        node_processes, executor, tmp_path, capsys):
    # the ILC memory of the Fig 7 task, learned in simulation (its 30 trials of 30 s, without
    # the camera), so that a single short trial reaches the target. Over DDS the ball position
    # the controller uses is 0.03-0.25 s old (camera latency, the 5 Hz camera and control
    # timers' phase), which the memory was not learned with: in-process replays of that age
    # (and of a simulator 10 % slow) stayed within 3.6 mm after 5 s before issue 18's timing
    learned = run_trials(SoftArmPlant(1, NOISE_FREE), PidIlcController(1), START, TARGET, 30,
                         30.0, keep_trajectories=False)
    memory_path = tmp_path / 'ilc.npz'
    np.savez(memory_path, targets_mm=np.array([[100, 110, 670]]), memories=learned.memory)

    # sra_sim with its defaults: the camera on, no ball_position of its own
    node_processes.start('inflarm_hw', 'sra_sim', parameters={'seed': 7})
    node_processes.start('inflarm_vision', 'ball_tracker')
    node_processes.start('inflarm_control', 'pressure_controller', parameters={
        'trial_duration_s': TRIAL_S, 'ilc_memory_path': str(memory_path)})
    probe = rclpy.create_node('probe', context=executor.context)
    truth: list[np.ndarray] = []
    points: list[PointStamped] = []
    reports: list[TrialReport] = []
    probe.create_subscription(
        PointStamped, 'end_point_truth',
        lambda m: truth.append(np.array([m.point.x, m.point.y, m.point.z])), SENSOR_QOS)
    probe.create_subscription(PointStamped, 'ball_position', points.append, SENSOR_QOS)
    probe.create_subscription(
        String, 'trial_report', lambda m: reports.append(decode(m.data, TrialReport)),
        RELIABLE_QOS)
    task_pub = probe.create_publisher(String, 'control_task', RELIABLE_QOS)
    executor.add_node(probe)
    assert spin_until(executor, lambda: task_pub.get_subscription_count() == 1 and truth
                      and len(points) >= 3, timeout_s=30.0), node_processes.output()
    assert node_processes.wait_for_output('ready: 5.0 Hz, 1 ILC memories'), \
        node_processes.output()
    publishers = probe.get_publishers_info_by_topic('ball_position')
    assert [p.node_name for p in publishers] == ['ball_tracker']
    start_error = np.abs(truth[-1] - TARGET)

    task = to_string_msg(ControlTask('sra_mount', tuple(TARGET), 'pid_ilc', 0))
    started = 'trial 0 (pid_ilc, ILC memory)'
    for _ in range(5):  # the controller takes a task once it has a ball position of its own
        task_pub.publish(task)
        if spin_until(executor, lambda: started in node_processes.output(), timeout_s=3.0):
            break
    assert started in node_processes.output(), node_processes.output()
    assert spin_until(executor, lambda: reports, timeout_s=TRIAL_S + 20.0), \
        node_processes.output()[-3000:]

    final_error = np.abs(truth[-1] - TARGET)
    with capsys.disabled():
        print(f'\n[camera loop, {TRIAL_S:.0f} s pid_ilc trial over DDS] RMSE '
              f'{np.round(np.array(reports[0].rmse) * 1000, 1).tolist()} mm, reach time '
              f'{reports[0].reach_time} s, final true error '
              f'{np.round(final_error * 1000, 1).tolist()} mm')
    assert np.all(start_error > 0.05)
    assert np.all(final_error < 5e-3), (final_error, node_processes.output()[-3000:])
    # within 5 mm of the target on every axis, as the camera measured it, in a few seconds
    reach = reports[0].reach_time
    # the paper's 8 s (its conclusion); one run measured 7.2, 7.4, 5.8 s (in-process, measured
    # exactly: 6.4, 7.4, 5.4 s)
    assert all(t is not None and t <= 8.0 for t in reach), (reach, reports[0].rmse)
