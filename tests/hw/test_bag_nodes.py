"""bag_recorder and bag_player in-process, over real DDS: what is recorded reads back equal, and
what is replayed arrives complete, in order, intact and with its timing roughly kept."""

import time

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
import yaml

from inflarm_hw.bag import (
    BagWriter,
    TopicQos,
    bag_info,
    deserialize,
    read_messages,
    serialize,
    typestore,
)
from inflarm_hw.nodes.bag_player import BagPlayer
from inflarm_hw.nodes.bag_recorder import BagRecorder
from inflarm_msgs_json.ros.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
from ros_harness import spin_until

JOINT_STATE = 'sensor_msgs/msg/JointState'
STRING = 'std_msgs/msg/String'
T0 = 1_700_000_000_000_000_000  # [ns]
RELIABLE_DEEP = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)


def overrides(**values) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


def joint_state_msg(i: int) -> JointState:
    msg = JointState(name=['joint_1', 'joint_2', 'joint_3'], position=[0.1 * i, -0.2 * i, 0.3],
                     velocity=[], effort=[1.0 + i, 2.0, -3.5])
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1000 + i, 500 * i
    msg.header.frame_id = 'base_link'
    return msg


# --- bag_recorder -----------------------------------------------------------------------------


def test_recorder_records_a_latched_topic_published_before_it_started(executor, tmp_path):
    # robot_description is latched and published once, long before any recorder exists.
    source = rclpy.create_node('source', context=executor.context)
    description_pub = source.create_publisher(String, 'robot_description', LATCHED_QOS)
    description_pub.publish(String(data='<robot name="arm"/>'))
    executor.add_node(source)
    executor.spin_once(timeout_sec=0.1)
    bag = tmp_path / 'latched'
    recorder = BagRecorder(context=executor.context, parameter_overrides=overrides(
        topics=['robot_description'], output=str(bag)))
    executor.add_node(recorder)
    assert spin_until(executor, lambda: recorder.bag.counts.get('/robot_description') == 1), \
        recorder.bag.counts
    executor.remove_node(recorder)
    recorder.destroy_node()
    info = bag_info(bag)
    assert info.topics['/robot_description'].offered_qos[0].durability == 'transient_local'
    [message] = read_messages(bag)
    assert deserialize(message.data, message.msgtype).data == '<robot name="arm"/>'
    # Jazzy's rosbag2 metadata: version 9, a type description hash per topic.
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['version'] == 9
    topic = metadata['topics_with_message_count'][0]['topic_metadata']
    assert topic['type_description_hash'].startswith('RIHS01_')


def test_recorder_records_a_sensor_and_a_reliable_topic_and_the_bag_reads_back_equal(
        executor, tmp_path):
    bag = tmp_path / 'run'
    # The recorder starts first: it finds the topics when their publishers appear.
    recorder = BagRecorder(context=executor.context, parameter_overrides=overrides(
        topics=['joint_states', 'report'], output=str(bag), storage='mcap'))
    executor.add_node(recorder)
    executor.spin_once(timeout_sec=0.3)
    assert not bag.joinpath('metadata.yaml').exists()
    source = rclpy.create_node('source', context=executor.context)
    joints_pub = source.create_publisher(JointState, 'joint_states', SENSOR_QOS)
    report_pub = source.create_publisher(String, 'report', RELIABLE_QOS)
    executor.add_node(source)
    assert spin_until(executor, lambda: joints_pub.get_subscription_count() >= 1
                      and report_pub.get_subscription_count() >= 1), 'recorder never subscribed'

    sent_joints = [joint_state_msg(i) for i in range(20)]
    sent_reports = [String(data=f'report {i} ü') for i in range(10)]
    for i, msg in enumerate(sent_joints):
        joints_pub.publish(msg)
        if i % 2 == 0:
            report_pub.publish(sent_reports[i // 2])
        executor.spin_once(timeout_sec=0.01)
    assert spin_until(executor, lambda: recorder.bag.counts == {'/joint_states': 20,
                                                                '/report': 10}), \
        recorder.bag.counts

    executor.remove_node(recorder)
    recorder.destroy_node()  # closes the bag
    info = bag_info(bag)
    assert info.storage == 'mcap' and info.message_count == 30
    assert info.topics['/joint_states'].msgtype == JOINT_STATE
    assert info.topics['/joint_states'].offered_qos[0].reliability == 'best_effort'
    assert info.topics['/report'].offered_qos[0].reliability == 'reliable'

    messages = list(read_messages(bag))
    stamps = [m.timestamp_ns for m in messages]
    assert stamps == sorted(stamps)
    assert abs(stamps[-1] * 1e-9 - time.time()) < 60.0  # receive times on the system clock
    joints = [deserialize(m.data, m.msgtype) for m in messages if m.topic == '/joint_states']
    reports = [deserialize(m.data, m.msgtype).data for m in messages if m.topic == '/report']
    assert reports == [m.data for m in sent_reports]
    assert len(joints) == len(sent_joints)
    for got, sent in zip(joints, sent_joints, strict=True):
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == (
            sent.header.stamp.sec, sent.header.stamp.nanosec)
        assert got.header.frame_id == 'base_link' and list(got.name) == list(sent.name)
        np.testing.assert_array_equal(got.position, sent.position)
        np.testing.assert_array_equal(got.effort, sent.effort)
        assert got.velocity.size == 0


def test_recorder_counts_each_topic_s_matched_publishers_as_they_come_and_go(executor,
                                                                            tmp_path):
    # A topic is found by its first publisher; a second one (the bag regression's three nodes
    # on /callback_log) is matched on its own: a run waits for the count, not for the topic.
    source = rclpy.create_node('source', context=executor.context)
    first = source.create_publisher(String, 'report', RELIABLE_QOS)
    executor.add_node(source)
    recorder = BagRecorder(context=executor.context, parameter_overrides=overrides(
        topics=['report'], output=str(tmp_path / 'run')))
    executor.add_node(recorder)
    assert spin_until(executor, lambda: recorder.matched_publishers.get('/report') == 1), \
        recorder.matched_publishers
    other = rclpy.create_node('other', context=executor.context)
    second = other.create_publisher(String, 'report', RELIABLE_QOS)
    executor.add_node(other)
    assert spin_until(executor, lambda: recorder.matched_publishers['/report'] == 2), \
        recorder.matched_publishers
    # Matched means recorded: what the second publisher sends now is in the bag.
    second.publish(String(data='from the second'))
    assert spin_until(executor, lambda: recorder.bag.counts.get('/report') == 1)
    other.destroy_publisher(second)
    assert spin_until(executor, lambda: recorder.matched_publishers['/report'] == 1), \
        recorder.matched_publishers
    first.publish(String(data='from the first'))
    assert spin_until(executor, lambda: recorder.bag.counts.get('/report') == 2)
    for node in (recorder, other, source):
        executor.remove_node(node)
        node.destroy_node()
    assert [deserialize(m.data, m.msgtype).data for m in read_messages(tmp_path / 'run')] == [
        'from the second', 'from the first']


def test_recorder_defaults_and_rejected_parameters(ros_context, tmp_path):
    recorder = BagRecorder(context=ros_context, parameter_overrides=overrides(
        topics=['joint_states'], output=str(tmp_path / 'a')))
    try:
        assert recorder.params['storage'] == 'sqlite3'
        assert recorder.params['discovery_timeout_s'] == 5.0
        assert recorder.topics == ['/joint_states']
        for name, value in (('output', 'elsewhere'), ('discovery_timeout_s', 0.0)):
            result = recorder.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful, name
    finally:
        recorder.destroy_node()
    assert bag_info(tmp_path / 'a').message_count == 0  # an empty but complete bag

    with pytest.raises(ValueError, match="parameter 'topics' is required"):
        BagRecorder(context=ros_context, parameter_overrides=overrides(output=str(tmp_path / 'b')))
    with pytest.raises(ValueError, match='exists: a bag is never written over'):
        BagRecorder(context=ros_context, parameter_overrides=overrides(
            topics=['x'], output=str(tmp_path / 'a')))
    with pytest.raises(ValueError, match='storage must be one of'):
        BagRecorder(context=ros_context, parameter_overrides=overrides(
            topics=['x'], output=str(tmp_path / 'c'), storage='bag1'))
    with pytest.raises(ValueError, match='more than once'):
        BagRecorder(context=ros_context, parameter_overrides=overrides(
            topics=['x', '/x'], output=str(tmp_path / 'd')))
    assert not (tmp_path / 'b').exists() and not (tmp_path / 'c').exists()


# --- bag_player -------------------------------------------------------------------------------


def write_bag(path, n_joints: int, joint_period_ns: int, n_reports: int = 0,
              report_period_ns: int = 1) -> None:
    types = typestore().types
    with BagWriter(path) as bag:
        bag.add_topic('joint_states', JOINT_STATE, [TopicQos('best_effort', 'volatile', depth=5)])
        for i in range(n_joints):
            msg = types[JOINT_STATE](
                header=types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=1000 + i, nanosec=0),
                    frame_id='base_link'),
                name=['joint_1', 'joint_2', 'joint_3'], position=np.array([i, 0.5, -i]) * 0.01,
                velocity=np.zeros(0), effort=np.array([1.0, 2.0, float(i)]))
            bag.write('joint_states', T0 + i * joint_period_ns, serialize(msg, JOINT_STATE))
        if n_reports:
            bag.add_topic('report', STRING, [TopicQos('reliable', 'volatile', depth=10)])
            for i in range(n_reports):
                bag.write('report', T0 + i * report_period_ns + 1,
                          serialize(types[STRING](data=f'report {i}'), STRING))


class Listener:
    """Records what arrives on joint_states and report, with steady receive times."""

    def __init__(self, executor) -> None:
        self.node = rclpy.create_node('listener', context=executor.context)
        self.joints: list[tuple[float, JointState]] = []
        self.reports: list[str] = []
        self.sensor_joints = 0
        self.node.create_subscription(
            JointState, 'joint_states',
            lambda m: self.joints.append((time.monotonic(), m)), RELIABLE_DEEP)
        self.node.create_subscription(  # best effort, as load_estimator subscribes
            JointState, 'joint_states', lambda m: setattr(
                self, 'sensor_joints', self.sensor_joints + 1), SENSOR_QOS)
        self.node.create_subscription(String, 'report', lambda m: self.reports.append(m.data),
                                      RELIABLE_DEEP)
        executor.add_node(self.node)


def test_player_replays_every_message_in_order_intact_with_the_timing_scaled(
        executor, tmp_path):
    write_bag(tmp_path / 'bag', n_joints=61, joint_period_ns=20_000_000, n_reports=7,
              report_period_ns=200_000_000)  # 1.2 s of recording
    listener = Listener(executor)
    player = BagPlayer(context=executor.context, parameter_overrides=overrides(
        input=str(tmp_path / 'bag'), rate=2.0, start_delay_s=0.5))
    executor.add_node(player)
    assert spin_until(executor, lambda: player.done, timeout_s=10.0)
    assert spin_until(executor, lambda: len(listener.joints) >= 61 and len(listener.reports) >= 7,
                      timeout_s=3.0), (len(listener.joints), len(listener.reports))

    assert player.played == 68
    assert len(listener.joints) == 61
    assert listener.reports == [f'report {i}' for i in range(7)]
    assert listener.sensor_joints > 0  # a best-effort subscriber gets the replay too
    for i, (_, msg) in enumerate(listener.joints):
        assert msg.header.stamp.sec == 1000 + i  # in order, headers as recorded
        assert list(msg.name) == ['joint_1', 'joint_2', 'joint_3']
        np.testing.assert_allclose(msg.position, np.array([i, 0.5, -i]) * 0.01, rtol=0, atol=0)
        assert list(msg.effort) == [1.0, 2.0, float(i)]
    span = listener.joints[-1][0] - listener.joints[0][0]
    assert 0.4 < span < 1.0, f'1.2 s at rate 2 played in {span:.3f} s'


def test_player_loops_and_replays_latched_topics_latched(executor, tmp_path):
    write_bag(tmp_path / 'bag', n_joints=5, joint_period_ns=40_000_000)
    listener = Listener(executor)
    player = BagPlayer(context=executor.context, parameter_overrides=overrides(
        input=str(tmp_path / 'bag'), rate=4.0, loop=True, start_delay_s=0.3))
    executor.add_node(player)
    assert spin_until(executor, lambda: len(listener.joints) >= 12, timeout_s=10.0)
    assert player.passes >= 3
    assert [m.header.stamp.sec for _, m in listener.joints[:12]] == [1000, 1001, 1002, 1003,
                                                                       1004] * 2 + [1000, 1001]
    assert player.set_parameters([Parameter('loop', value=False)])[0].successful
    assert spin_until(executor, lambda: player.done, timeout_s=5.0)
    executor.remove_node(player)
    player.destroy_node()

    types = typestore().types
    with BagWriter(tmp_path / 'latched') as bag:
        bag.add_topic('robot_description', STRING,
                      [TopicQos('reliable', 'transient_local', depth=1)])
        bag.write('robot_description', T0, serialize(types[STRING](data='<robot/>'), STRING))
    player = BagPlayer(context=executor.context, parameter_overrides=overrides(
        input=str(tmp_path / 'latched'), start_delay_s=0.0))
    executor.add_node(player)
    assert spin_until(executor, lambda: player.done, timeout_s=5.0)
    received = []
    listener.node.create_subscription(String, 'robot_description',
                                      lambda m: received.append(m.data), LATCHED_QOS)
    assert spin_until(executor, lambda: received == ['<robot/>'], timeout_s=5.0), received


def test_player_publishes_the_bag_time_on_clock(executor, tmp_path):
    write_bag(tmp_path / 'bag', n_joints=20, joint_period_ns=50_000_000)  # 1 s of bag time
    listener = Listener(executor)
    clock = []
    listener.node.create_subscription(Clock, '/clock', clock.append, 10)
    player = BagPlayer(context=executor.context, parameter_overrides=overrides(
        input=str(tmp_path / 'bag'), start_delay_s=0.2, clock_rate_hz=50.0))
    executor.add_node(player)
    end = player.info.start_ns + player.info.duration_ns
    assert spin_until(executor, lambda: player.done, timeout_s=10.0)
    assert spin_until(executor, lambda: Time.from_msg(clock[-1].clock).nanoseconds == end)
    times = [Time.from_msg(m.clock).nanoseconds for m in clock]
    assert len(times) > 10 and times == sorted(times)  # never backwards within a pass
    assert times[0] >= player.info.start_ns


def test_player_errors_name_the_problem(ros_context, tmp_path):
    with pytest.raises(ValueError, match="parameter 'input' is required"):
        BagPlayer(context=ros_context)
    with pytest.raises(ValueError, match='no bag at'):
        BagPlayer(context=ros_context, parameter_overrides=overrides(
            input=str(tmp_path / 'missing')))
    write_bag(tmp_path / 'bag', n_joints=2, joint_period_ns=1)
    with pytest.raises(ValueError, match=r"topics \['/camera'\] are not in the bag"):
        BagPlayer(context=ros_context, parameter_overrides=overrides(
            input=str(tmp_path / 'bag'), topics=['camera']))
    player = BagPlayer(context=ros_context, parameter_overrides=overrides(
        input=str(tmp_path / 'bag'), topics=['joint_states']))
    try:
        assert player.params['rate'] == 1.0 and player.params['loop'] is False
        assert player.params['start_delay_s'] == 1.0
        assert player.topics == ['/joint_states'] and player.total == 2
        for name, value in (('rate', 0.0), ('input', 'other'), ('start_delay_s', 2.0)):
            assert not player.set_parameters([Parameter(name, value=value)])[0].successful, name
    finally:
        player.destroy_node()
