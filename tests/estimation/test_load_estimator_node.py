"""load_estimator in-process: estimates from joint_states, skips bad samples, guards wrinkling.

Efforts are the torques the motors apply (ros2_control), the negative of the paper's tau_m.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, WrenchStamped
import numpy as np
import rclpy
from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from inflarm_estimation.nodes.load_estimator import LoadEstimator
from inflarm_model.elastostatics import motor_torques, spring_deflections
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS, wrinkling_moment
from inflarm_msgs_json import LinkStatus, decode
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS
from ros_harness import spin_until

ARM = FlexibleArm(0.6, 0.03)
FORCE = np.array([0.0, 10.0, -15.0])


def loaded_sample(q_m, force=FORCE) -> tuple[np.ndarray, np.ndarray]:
    """Motor angles and the torques that hold ``force`` (the forward problem)."""
    q_k = spring_deflections(ARM, q_m, force, MEAN_STIFFNESS).q_k
    q = FlexibleArm.assemble_q(q_m, q_k)
    return q_k, motor_torques(ARM, q, force)


class Rig:
    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.node = LoadEstimator(context=executor.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.out = {'wrench': [], 'tip': [], 'links': [], 'diagnostics': [],
                    'pose': []}
        for topic, kind, key in (('estimated_wrench', WrenchStamped, 'wrench'),
                                 ('estimated_joint_states', JointState, 'pose'),
                                 ('estimated_tip', PointStamped, 'tip'),
                                 ('link_status', String, 'links'),
                                 ('diagnostics', DiagnosticArray, 'diagnostics')):
            self.probe.create_subscription(kind, topic, self.out[key].append, RELIABLE_QOS)
        self.pub = self.probe.create_publisher(JointState, 'joint_states', JOINT_STATE_QOS)
        executor.add_node(self.node)
        executor.add_node(self.probe)
        assert spin_until(executor, lambda: self.pub.get_subscription_count() == 1)

    def send(self, names, positions, load_torques) -> None:
        """A joint state whose motors hold ``load_torques`` (tau_m): they apply -tau_m."""
        self.pub.publish(JointState(name=names, position=list(positions),
                                    effort=[-float(t) for t in load_torques]))

    def idle(self, seconds: float = 0.5) -> None:
        spin_until(self.executor, lambda: False, timeout_s=seconds)


def test_a_sample_yields_load_deflections_tip_and_link_status(executor):
    rig = Rig(executor)
    q_m = np.array([0.2, 0.5, -1.1])
    q_k, tau_m = loaded_sample(q_m)
    # extra joints and any order are fine
    rig.send(['gripper', 'joint_3', 'joint_1', 'joint_2'], [0.0, q_m[2], q_m[0], q_m[1]],
             [0.0, tau_m[2], tau_m[0], tau_m[1]])
    assert spin_until(executor, lambda: len(rig.out['links']) == 2 and rig.out['tip']
                      and rig.out['diagnostics'])
    # The wrench is stamped at the tip, in its frame: turned back to the base it is the load.
    wrench = rig.out['wrench'][0]
    assert wrench.header.frame_id == 'tip'
    pose = ARM.fk(FlexibleArm.assemble_q(q_m, q_k))
    f = wrench.wrench.force
    np.testing.assert_allclose(pose[:3, :3] @ [f.x, f.y, f.z], FORCE, atol=1e-6)
    torque = wrench.wrench.torque
    assert [torque.x, torque.y, torque.z] == [0.0, 0.0, 0.0]  # a pure force at the tip
    tip = rig.out['tip'][0].point
    np.testing.assert_allclose([tip.x, tip.y, tip.z], pose[:3, 3], atol=1e-9)
    # The whole deflected pose, every URDF joint, for robot_state_publisher; the efforts
    # are the motors' torques and the springs' k q_k.
    estimated = rig.out['pose'][0]
    assert list(estimated.name) == list(FlexibleArm.JOINT_NAMES)
    np.testing.assert_allclose(estimated.position, FlexibleArm.assemble_q(q_m, q_k),
                               atol=1e-9)
    np.testing.assert_allclose(estimated.effort, FlexibleArm.assemble_q(-tau_m, MEAN_STIFFNESS
                                                                        * q_k), atol=1e-6)
    statuses = [decode(m.data, expected=LinkStatus) for m in rig.out['links']]
    assert [s.link for s in statuses] == ['link_1', 'link_2']
    assert statuses[0].wrinkling_moment == wrinkling_moment(50e3, 0.055)
    assert statuses[0].moment > statuses[1].moment > 0.0  # link 1 carries the longer lever
    assert rig.out['diagnostics'][-1].status[0].level == DiagnosticStatus.OK


def test_bad_samples_are_skipped_and_the_node_keeps_going(executor):
    rig = Rig(executor)
    q_m = np.array([0.2, 0.5, -1.1])
    _, tau_m = loaded_sample(q_m)
    names = ['joint_1', 'joint_2', 'joint_3']
    rig.send(names[:2], q_m[:2], tau_m[:2])  # a motor missing
    rig.send(names, q_m, [])  # no efforts
    rig.send(names, [np.nan, 0.5, -1.1], tau_m)  # NaN
    rig.send(names, [10.0, 0.5, -1.1], tau_m)  # beyond the joint limits, though finite
    rig.send(names, [0.2, 1e10, -1.1], tau_m)
    rig.idle()
    assert rig.out['wrench'] == [] and rig.out['pose'] == []
    assert 'joint_2 at 1e+10 rad is outside its limits' in rig.node.problems.last['joint_states']
    assert rig.node.problems.counts['joint_states'] == 5
    assert rig.node.problems.unexpected == 0
    rig.send(names, q_m, tau_m)
    assert spin_until(executor, lambda: rig.out['wrench'])


def test_diagnostics_aggregate_about_once_a_second(executor):
    rig = Rig(executor)
    q_m = np.array([0.2, 0.5, -1.1])
    _, tau_m = loaded_sample(q_m)
    for i in range(30):
        rig.send(['joint_1', 'joint_2', 'joint_3'], q_m, tau_m)
        assert spin_until(executor, lambda: len(rig.out['wrench']) == i + 1)  # noqa: B023
    assert spin_until(executor, lambda: rig.out['diagnostics'], timeout_s=3.0)
    values = {kv.key: kv.value for d in rig.out['diagnostics'] for kv in d.status[0].values}
    assert len(rig.out['diagnostics']) <= 3  # not one per sample
    samples = sum(int(kv.value) for d in rig.out['diagnostics'] for kv in d.status[0].values
                  if kv.key == 'samples')
    assert samples == 30 and 'converged' in values


def test_no_subscription_takes_message_lost_events(executor):
    """Taking one can deadlock the node under steady losses (rmw_fastrtps 8.4: it hung in
    ``take_event`` at 1 kHz, `inflarm_msgs_json.ros.qos.subscription_events`)."""
    rig = Rig(executor)
    kinds = {h.event_type for s in rig.node.subscriptions for h in s.event_handlers}
    assert QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS in kinds
    assert QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST not in kinds


def test_a_singular_configuration_is_reported_not_estimated(executor):
    rig = Rig(executor)
    # joint_2 = pi/2 with joint_3 = 0: the arm stands along joint 1's axis, J_m loses rank
    rig.send(['joint_1', 'joint_2', 'joint_3'], [0.0, np.pi / 2, 0.0], [0.1, 0.2, 0.3])
    assert spin_until(executor, lambda: rig.out['diagnostics']
                      and rig.out['diagnostics'][-1].status[0].level != DiagnosticStatus.WARN)
    status = rig.out['diagnostics'][-1].status[0]
    assert status.level == DiagnosticStatus.ERROR
    assert status.message  # the reason
    spin_until(executor, lambda: False, timeout_s=0.3)
    assert rig.out['wrench'] == []


def test_low_pressure_shows_a_negative_margin(executor):
    rig = Rig(executor, **{'arm.link_pressure_pa': [10e3, 10e3]})
    q_m = np.array([0.0, 0.3, -0.6])
    _, tau_m = loaded_sample(q_m)
    rig.send(['joint_1', 'joint_2', 'joint_3'], q_m, tau_m)
    assert spin_until(executor, lambda: len(rig.out['links']) == 2)
    link_1 = decode(rig.out['links'][0].data, expected=LinkStatus)
    assert link_1.moment > link_1.wrinkling_moment  # 18 N at ~1 m on a 10 kPa link
    assert link_1.margin < 0.0


def test_a_stalled_stream_is_reported_stale(executor):
    rig = Rig(executor, stall_timeout_s=0.2)
    assert spin_until(executor, lambda: rig.out['diagnostics'], timeout_s=3.0)
    before = rig.out['diagnostics'][-1].status[0]
    assert before.level == DiagnosticStatus.WARN and 'no joint_states' in before.message
    q_m = np.array([0.2, 0.5, -1.1])
    _, tau_m = loaded_sample(q_m)
    rig.send(['joint_1', 'joint_2', 'joint_3'], q_m, tau_m)
    assert spin_until(executor, lambda: rig.out['wrench'])
    # then nothing: the next reports say the stream stalled, and for how long
    assert spin_until(executor, lambda: rig.out['diagnostics'][-1].status[0].level
                      == DiagnosticStatus.STALE, timeout_s=3.0)
    status = rig.out['diagnostics'][-1].status[0]
    assert 'joint_states stalled' in status.message
    values = {kv.key: kv.value for kv in status.values}
    assert float(values['seconds_since_sample']) > 0.2
    rig.send(['joint_1', 'joint_2', 'joint_3'], q_m, tau_m)  # the stream resumes
    assert spin_until(executor, lambda: rig.out['diagnostics'][-1].status[0].level
                      == DiagnosticStatus.OK, timeout_s=3.0)
