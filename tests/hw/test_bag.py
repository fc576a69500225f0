"""The bag core: real rosbag2 bags (sqlite3 and MCAP) written, read back, decoded; clear errors.
And inflarm-estimate-bag on bags of known loads."""

import numpy as np
import pytest

from inflarm_bringup.bag_estimate import main as estimate_bag
from inflarm_hw.bag import (
    BagWriter,
    TopicQos,
    bag_info,
    deserialize,
    read_messages,
    serialize,
    typestore,
)
from inflarm_model.elastostatics import motor_torques, spring_deflections
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS

JOINT_STATE = 'sensor_msgs/msg/JointState'
STRING = 'std_msgs/msg/String'
T0 = 1_700_000_000_000_000_000  # [ns]


def joint_state(i: int, rng: np.random.Generator):
    types = typestore().types
    stamp = types['builtin_interfaces/msg/Time'](sec=T0 // 10**9 + i, nanosec=i * 1000)
    return types[JOINT_STATE](
        header=types['std_msgs/msg/Header'](stamp=stamp, frame_id='base_link'),
        name=['joint_1', 'joint_2', 'joint_3'], position=rng.normal(size=3),
        velocity=np.zeros(0), effort=rng.normal(size=3))


def string(text: str):
    return typestore().types[STRING](data=text)


def write_sample_bag(path, storage: str, n: int = 20) -> tuple[list, list]:
    """n joint states every 20 ms and a string every 100 ms; returns both lists."""
    rng = np.random.default_rng(7)
    joints = [joint_state(i, rng) for i in range(n)]
    strings = [string(f'report {i}') for i in range(n // 5)]
    with BagWriter(path, storage=storage) as bag:
        bag.add_topic('joint_states', JOINT_STATE,
                      offered_qos=[TopicQos('best_effort', 'volatile', depth=5)])
        bag.add_topic('/report', STRING)
        for i, msg in enumerate(joints):
            bag.write('joint_states', T0 + i * 20_000_000, serialize(msg, JOINT_STATE))
        for i, msg in enumerate(strings):
            bag.write('/report', T0 + i * 100_000_000 + 1, serialize(msg, STRING))
        assert bag.counts == {'/joint_states': n, '/report': n // 5}
    return joints, strings


def assert_joint_states_equal(actual, expected) -> None:
    assert actual.header.stamp.sec == expected.header.stamp.sec
    assert actual.header.stamp.nanosec == expected.header.stamp.nanosec
    assert actual.header.frame_id == expected.header.frame_id
    assert list(actual.name) == list(expected.name)
    for field in ('position', 'velocity', 'effort'):
        np.testing.assert_array_equal(getattr(actual, field), getattr(expected, field))


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_written_bag_reads_back_in_time_order_with_the_same_messages(tmp_path, storage):
    joints, strings = write_sample_bag(tmp_path / 'bag', storage)
    assert (tmp_path / 'bag' / 'metadata.yaml').is_file()

    messages = list(read_messages(tmp_path / 'bag'))
    assert len(messages) == len(joints) + len(strings)
    stamps = [m.timestamp_ns for m in messages]
    assert stamps == sorted(stamps)
    decoded_joints = [deserialize(m.data, m.msgtype) for m in messages
                      if m.topic == '/joint_states']
    decoded_strings = [deserialize(m.data, m.msgtype).data for m in messages
                       if m.topic == '/report']
    assert {(m.topic, m.msgtype) for m in messages} == {('/joint_states', JOINT_STATE),
                                                        ('/report', STRING)}
    assert decoded_strings == [s.data for s in strings]
    assert len(decoded_joints) == len(joints)
    for actual, expected in zip(decoded_joints, joints, strict=True):
        assert_joint_states_equal(actual, expected)


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_bag_info_reports_topics_counts_times_storage_and_offered_qos(tmp_path, storage):
    write_sample_bag(tmp_path / 'bag', storage, n=20)
    info = bag_info(tmp_path / 'bag')
    assert info.storage == storage
    assert info.message_count == 24
    assert info.start_ns == T0
    assert info.duration_ns == 19 * 20_000_000
    assert info.topics['/joint_states'].msgtype == JOINT_STATE
    assert info.topics['/joint_states'].message_count == 20
    assert info.topics['/joint_states'].offered_qos == (
        TopicQos('best_effort', 'volatile', 'keep_last', 5),)
    assert info.topics['/report'].message_count == 4
    assert info.topics['/report'].offered_qos == ()


def test_read_messages_selects_topics_by_relative_or_absolute_name(tmp_path):
    write_sample_bag(tmp_path / 'bag', 'sqlite3')
    assert {m.topic for m in read_messages(tmp_path / 'bag', ['report'])} == {'/report'}
    assert len(list(read_messages(tmp_path / 'bag', ['/joint_states']))) == 20
    assert list(read_messages(tmp_path / 'bag', [])) == []


def test_an_empty_bag_is_readable(tmp_path):
    with BagWriter(tmp_path / 'empty', storage='mcap') as bag:
        bag.add_topic('joint_states', JOINT_STATE)
    info = bag_info(tmp_path / 'empty')
    assert info.message_count == 0 and info.duration_ns == 0
    assert info.topics['/joint_states'].message_count == 0
    assert list(read_messages(tmp_path / 'empty')) == []


def test_reading_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match='no bag at'):
        read_messages(tmp_path / 'missing')
    (tmp_path / 'not_a_bag').mkdir()
    with pytest.raises(ValueError, match='has no metadata.yaml'):
        bag_info(tmp_path / 'not_a_bag')
    write_sample_bag(tmp_path / 'bag', 'sqlite3')
    with pytest.raises(ValueError, match=r"topics \['/camera'\] are not in the bag"):
        read_messages(tmp_path / 'bag', ['joint_states', 'camera'])
    with pytest.raises(ValueError, match='expected a list of topic names'):
        read_messages(tmp_path / 'bag', 'joint_states')


def test_writing_errors_name_the_problem(tmp_path):
    (tmp_path / 'exists').mkdir()
    with pytest.raises(ValueError, match='exists: a bag is never written over'):
        BagWriter(tmp_path / 'exists')
    with pytest.raises(ValueError, match='expected storage one of'):
        BagWriter(tmp_path / 'a', storage='rosbag1')
    with BagWriter(tmp_path / 'b') as bag:
        with pytest.raises(ValueError, match="unknown message type 'my_msgs/msg/Foo'"):
            bag.add_topic('foo', 'my_msgs/msg/Foo')
        bag.add_topic('joint_states', JOINT_STATE)
        with pytest.raises(ValueError, match='already added'):
            bag.add_topic('/joint_states', JOINT_STATE)
        with pytest.raises(ValueError, match='was not added'):
            bag.write('other', T0, b'\x00\x01\x00\x00')
        with pytest.raises(ValueError, match='expected a topic name'):
            bag.add_topic('', STRING)
        with pytest.raises(ValueError, match='non-negative int'):
            bag.write('joint_states', -1, b'')
    with pytest.raises(ValueError, match='is closed'):
        bag.write('joint_states', T0, b'')
    with pytest.raises(ValueError, match='expected reliability one of'):
        TopicQos('sometimes')


def test_deserialize_rejects_bytes_that_are_not_the_type():
    raw = serialize(string('hello'), STRING)
    assert deserialize(raw, STRING).data == 'hello'
    with pytest.raises(ValueError, match='cannot decode .* as sensor_msgs/msg/JointState'):
        deserialize(raw[:-2], JOINT_STATE)
    with pytest.raises(ValueError, match='unknown message type'):
        deserialize(raw, 'std_msgs/msg/Nope')


# --- inflarm-estimate-bag ---------------------------------------------------------------------


def write_loaded_arm_bag(path, force: np.ndarray, n: int = 8):
    """n noiseless joint states of the arm holding ``force`` at random poses (joints listed in
    a shuffled order), one sample without joint_2, and a String topic; returns the equilibria."""
    arm, rng, types = FlexibleArm(), np.random.default_rng(7), typestore().types
    equilibria = []
    with BagWriter(path) as bag:
        bag.add_topic('joint_states', JOINT_STATE)
        bag.add_topic('report', STRING)
        for i in range(n + 1):
            q_m = np.array([0.0, 0.6, -1.2]) + rng.uniform(-0.2, 0.2, 3)
            eq = spring_deflections(arm, q_m, force, MEAN_STIFFNESS)
            tau_m = motor_torques(arm, FlexibleArm.assemble_q(q_m, eq.q_k), force)
            order = [2, 0, 1] if i < n else [2, 0]  # the last sample lacks joint_2
            msg = types[JOINT_STATE](
                header=types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=100 + i, nanosec=0),
                    frame_id='base_link'),
                name=[f'joint_{j + 1}' for j in order], position=q_m[order],
                velocity=np.zeros(0), effort=-tau_m[order])  # the motors apply -tau_m
            bag.write('joint_states', T0 + i, serialize(msg, JOINT_STATE))
            equilibria.append(eq)
        bag.write('report', T0, serialize(string('not a joint state'), STRING))
    return equilibria[:n]


def test_estimate_bag_recovers_the_load_and_pose_of_every_sample(tmp_path, capsys):
    force = np.array([3.0, 10.0, -15.0])
    equilibria = write_loaded_arm_bag(tmp_path / 'bag', force)
    out = tmp_path / 'estimates.csv'
    assert estimate_bag([str(tmp_path / 'bag'), '--out', str(out)]) == 0
    summary = capsys.readouterr().out
    assert '8 samples (1 skipped), 8 converged; mean force [3.000, 10.000, -15.000] N' in summary
    assert out.read_text().splitlines()[0] == (
        'time_s,force_x_n,force_y_n,force_z_n,q_k1_rad,q_k2_rad,q_k3_rad,q_k4_rad,'
        'tip_x_m,tip_y_m,tip_z_m,converged')
    table = np.loadtxt(out, delimiter=',', skiprows=1)
    np.testing.assert_array_equal(table[:, 0], 100.0 + np.arange(8))
    np.testing.assert_allclose(table[:, 1:4], np.tile(force, (8, 1)), atol=1e-6)
    np.testing.assert_allclose(table[:, 4:8], [eq.q_k for eq in equilibria], atol=1e-9)
    np.testing.assert_allclose(table[:, 8:11], [eq.tip_position for eq in equilibria],
                               atol=1e-9)
    assert table[:, 11].tolist() == [1.0] * 8


def test_estimate_bag_fails_with_a_message_and_an_exit_status(tmp_path, capsys):
    write_loaded_arm_bag(tmp_path / 'bag', np.array([0.0, 10.0, -15.0]), n=2)
    bag, out = str(tmp_path / 'bag'), str(tmp_path / 'out.csv')
    cases = (
        ([str(tmp_path / 'missing'), '--out', out], 1, 'no bag at'),
        ([bag, '--out', out, '--topic', 'report'], 1, 'holds std_msgs/msg/String'),
        ([bag, '--out', out, '--topic', 'camera'], 1, "topics ['/camera'] are not in the bag"),
        ([bag, '--out', out, '--spring-offset', '0.7'], 1, 'spring_offset'),
        ([bag, '--out', out, '--stiffness', '100', '200'], 2, 'takes 1 or 4 values'),
        ([bag, '--out', out, '--stiffness', '-1'], 2, 'expected a positive finite number'),
        ([bag], 2, 'the following arguments are required: --out'),
    )
    for argv, status, message in cases:
        assert estimate_bag(argv) == status, argv
        assert message in capsys.readouterr().err, argv
    assert not (tmp_path / 'out.csv').exists()
