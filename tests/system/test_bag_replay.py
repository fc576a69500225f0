"""Record a simulated arm run with bag_recorder, estimate the load offline from the bag, and
replay it with bag_player into load_estimator: all as real processes over real DDS."""

import signal

import numpy as np
import pytest
import rclpy
from sensor_msgs.msg import JointState

from inflarm_bringup.bag_estimate import main as estimate_bag
from inflarm_hw.bag import bag_info, deserialize, read_messages
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS
from ros_harness import BaseFrameForces, spin_until

pytestmark = pytest.mark.system
LOAD = np.array([0.0, 10.0, -15.0])  # arm_sim's default tip load [N]
ARM_CONFIG = ('inflarm_model', 'inflatable_arm.yaml')
RECORDED_SAMPLES = 150  # 3 s of joint_states at 50 Hz


def stop(process) -> int:
    process.send_signal(signal.SIGINT)
    return process.wait(timeout=10.0)


def test_a_recorded_run_gives_the_simulated_load_offline_and_when_replayed(
        node_processes, executor, tmp_path, capsys):
    from ament_index_python.packages import get_package_share_directory
    arm_yaml = f'{get_package_share_directory(ARM_CONFIG[0])}/config/{ARM_CONFIG[1]}'
    bag = tmp_path / 'arm_run'
    probe = rclpy.create_node('probe', context=executor.context)
    joints: list[JointState] = []
    wrenches = BaseFrameForces(probe)
    probe.create_subscription(JointState, 'joint_states', joints.append, JOINT_STATE_QOS)
    executor.add_node(probe)

    # Record: arm_sim -> joint_states, tip_position_truth -> bag_recorder -> bag (SIGINT-stopped)
    sim = node_processes.start('inflarm_hw', 'arm_sim', '--params-file', arm_yaml,
                               parameters={'seed': 7})
    recorder = node_processes.start('inflarm_hw', 'bag_recorder', parameters={
        'topics': ['joint_states', 'tip_position_truth'], 'output': str(bag)})
    assert node_processes.wait_for_output('recording /joint_states'), node_processes.output()
    assert node_processes.wait_for_output('recording /tip_position_truth'), \
        node_processes.output()
    start = len(joints)
    assert spin_until(executor, lambda: len(joints) >= start + RECORDED_SAMPLES, timeout_s=15.0)
    assert stop(recorder) == 0, node_processes.output()
    assert stop(sim) == 0, node_processes.output()
    assert 'bag closed' in node_processes.output()

    info = bag_info(bag)  # the SIGINT-stopped recorder left a complete bag
    recorded = info.topics['/joint_states'].message_count
    # Nothing the recorder received is lost: every sample the probe saw between the bag's first
    # and last one is in it (best effort on both sides: a few may drop), however long its
    # subscription took to match arm_sim's publisher after 'recording'.
    def ns(stamp) -> int:
        return stamp.sec * 10**9 + stamp.nanosec

    stamps = [ns(deserialize(r.data, r.msgtype).header.stamp)
              for r in read_messages(bag, ['joint_states'])]
    seen = [ns(m.header.stamp) for m in joints]
    expected = [t for t in seen if stamps[0] <= t <= stamps[-1]]
    assert recorded >= RECORDED_SAMPLES // 2, info
    assert len(set(expected) - set(stamps)) <= 3, (len(expected), recorded)
    assert info.topics['/tip_position_truth'].message_count >= RECORDED_SAMPLES // 2, info

    # (a) Offline: inflarm-estimate-bag recovers the simulated load and the true tip.
    csv_path = tmp_path / 'estimates.csv'
    assert estimate_bag([str(bag), '--out', str(csv_path)]) == 0
    assert f'{recorded} samples (0 skipped), {recorded} converged' in capsys.readouterr().out
    table = np.loadtxt(csv_path, delimiter=',', skiprows=1, ndmin=2)
    assert table.shape == (recorded, 12) and table[:, 11].all()
    np.testing.assert_allclose(table[:, 1:4].mean(axis=0), LOAD, atol=0.3)
    truth = np.array([[m.point.x, m.point.y, m.point.z] for m in (
        deserialize(r.data, r.msgtype) for r in read_messages(bag, ['tip_position_truth']))])
    np.testing.assert_allclose(table[:, 8:11].mean(axis=0), truth.mean(axis=0), atol=2e-3)

    # (b) Replay: bag_player -> joint_states -> load_estimator -> estimated_wrench, same load.
    node_processes.start('inflarm_estimation', 'load_estimator', '--params-file', arm_yaml)
    node_processes.start('inflarm_hw', 'bag_player', parameters={
        'input': str(bag), 'topics': ['joint_states'], 'loop': True})
    assert spin_until(executor, lambda: len(wrenches) >= 50, timeout_s=20.0), \
        node_processes.output()
    forces = np.array([f for _, f in wrenches.forces])
    np.testing.assert_allclose(forces.mean(axis=0), LOAD, atol=0.3)
    stamps = np.array([t for t, _ in wrenches.forces])
    # The estimates are of the recorded samples: their stamps are the recorded ones.
    assert stamps.min() >= table[0, 0] - 1e-6 and stamps.max() <= table[-1, 0] + 1e-6
