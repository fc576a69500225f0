"""A soft-arm PID trial through hw_bridge + sim_mcu gives the trial report it gives on sra_sim."""

import signal

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
TARGET = (0.100, 0.110, 0.670)
TRIAL_S = 10.0


def run_trial(node_processes, executor, plant: list[tuple[str, dict]], tag: str):
    """Start ``plant`` and a pressure_controller, run one PID trial, stop them; the report and
    the final true end point."""
    names = []
    for executable, parameters in plant:
        names.append(f'{executable}_{tag}')
        node_processes.start('inflarm_hw', executable, parameters=parameters, name=names[-1])
    names.append(f'controller_{tag}')
    node_processes.start('inflarm_control', 'pressure_controller', name=names[-1],
                         parameters={'trial_duration_s': TRIAL_S})
    probe = rclpy.create_node(f'probe_{tag}', context=executor.context)
    truth, reports = [], []
    probe.create_subscription(
        PointStamped, 'end_point_truth',
        lambda m: truth.append(np.array([m.point.x, m.point.y, m.point.z])), SENSOR_QOS)
    probe.create_subscription(
        String, 'trial_report', lambda m: reports.append(decode(m.data, TrialReport)),
        RELIABLE_QOS)
    task_pub = probe.create_publisher(String, 'control_task', RELIABLE_QOS)
    executor.add_node(probe)
    try:
        assert spin_until(executor, lambda: task_pub.get_subscription_count() == 1 and truth,
                          timeout_s=20.0), node_processes.output()
        start = len(node_processes.output())
        # the controller takes a task once it has a ball position
        assert spin_until(executor, lambda: 'ready: 5.0 Hz' in node_processes.output()[start:]
                          or 'ready: 5.0 Hz' in node_processes.output(), 20.0)
        spin_until(executor, lambda: False, timeout_s=1.0)
        task_pub.publish(to_string_msg(ControlTask('sra_mount', TARGET, 'pid', 0)))
        assert spin_until(executor, lambda: reports, timeout_s=TRIAL_S + 20.0), \
            node_processes.output()[-3000:]
        final = truth[-1]
    finally:
        executor.remove_node(probe)
        probe.destroy_node()
    for name in names:
        process = node_processes.group.processes[name]
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=15.0) == 0, node_processes.output()[-3000:]
    return reports[0], final


def test_a_pid_trial_through_the_bridge_matches_the_simulator(
        node_processes, executor, tmp_path, capsys):
    direct, direct_end = run_trial(
        node_processes, executor, [('sra_sim', {'seed': 7})], 'direct')
    link = str(tmp_path / 'mcu')
    bridged, bridged_end = run_trial(
        node_processes, executor,
        [('sim_mcu', {'plant': 'sra', 'link': link, 'seed': 7}),
         ('hw_bridge', {'port': link, 'autostart': True})], 'bridge')
    with capsys.disabled():
        for name, report, end in (('sra_sim', direct, direct_end),
                                  ('hw_bridge + sim_mcu', bridged, bridged_end)):
            print(f'\n[trial {TRIAL_S:.0f} s, pid] {name}: RMSE '
                  f'{np.round(np.array(report.rmse) * 1000, 1).tolist()} mm, reach time '
                  f'{report.reach_time} s, final error '
                  f'{np.linalg.norm(end - TARGET) * 1000:.1f} mm')
    # the same within noise (0.5 mm camera noise, DDS and scheduling jitter of the 5 Hz loop)
    np.testing.assert_allclose(bridged.rmse, direct.rmse, rtol=0.15, atol=2e-3)
    for a, b in zip(bridged.reach_time, direct.reach_time, strict=True):
        assert (a is None) == (b is None) or min(x for x in (a, b) if x is not None) > \
            TRIAL_S - 2.0, (bridged.reach_time, direct.reach_time)
        if a is not None and b is not None:
            assert abs(a - b) <= 1.0, (bridged.reach_time, direct.reach_time)
    assert np.linalg.norm(bridged_end - direct_end) < 5e-3
