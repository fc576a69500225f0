"""inflarm-bag-regression: a simulated run recorded with bag_recorder (real processes over real
DDS, the nodes under test publishing their callback records) replays every output exactly,
identically twice; a record whose message the recorder lost is skipped and counted; it fails on
a changed parameter naming the topic, and rejects a bag without callback records."""

import dataclasses
import pathlib
import signal
import zlib

from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_msgs.msg import String
import yaml

from inflarm_bringup.bag_compare import DEFAULT_TOLERANCES, compare, stamp_ns
from inflarm_bringup.bag_regression import main, regression, replay
from inflarm_hw.bag import BagWriter, bag_info, deserialize, read_messages, serialize, typestore
from inflarm_msgs_json import ControlTask, TrialReport, decode, encode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import COMMAND_QOS, RELIABLE_QOS, SENSOR_QOS
from ros_harness import NodeProcesses, lock_free_domain, spin_until

pytestmark = pytest.mark.system
ARM_CONFIG = ('inflarm_model', 'inflatable_arm.yaml')
INPUTS = ['joint_states', 'tip_trajectory', 'ball_position', 'control_task']
RECORDS = 'callback_log'
OUTPUTS = ['estimated_joint_states', 'estimated_wrench', 'estimated_tip', 'link_status',
           'motor_position_command', 'chamber_pressure_command', 'trial_report']
TRIAL_S = 4.0
TARGET = (0.100, 0.110, 0.670)
# The run's parameters that differ from the installed configs: what a user passes with
# --params-file to replay their own run.
RUN_PARAMETERS = {'pressure_controller': {'trial_duration_s': TRIAL_S}}
UNDER_TEST = {'callback_log': True}


def _stop(process) -> int:
    process.send_signal(signal.SIGINT)
    return process.wait(timeout=15.0)


def record_run(node_processes, executor, bag: pathlib.Path, params_file: pathlib.Path) -> None:
    """Both simulated arms with their estimator and controllers, recorded by bag_recorder: a
    tip trajectory for the inflatable arm, a PID trial for the soft arm."""
    from ament_index_python.packages import get_package_share_directory
    arm_yaml = f'{get_package_share_directory(ARM_CONFIG[0])}/config/{ARM_CONFIG[1]}'
    probe = rclpy.create_node('probe', context=executor.context)
    tips: list[PointStamped] = []
    wrenches: list[WrenchStamped] = []
    reports: list[TrialReport] = []
    commands: list[JointState] = []
    probe.create_subscription(PointStamped, 'tip_position_truth', tips.append, SENSOR_QOS)
    probe.create_subscription(WrenchStamped, 'estimated_wrench', wrenches.append, RELIABLE_QOS)
    probe.create_subscription(JointState, 'motor_position_command', commands.append,
                              COMMAND_QOS)
    probe.create_subscription(String, 'trial_report', lambda m: reports.append(decode(m.data)),
                              RELIABLE_QOS)
    path_pub = probe.create_publisher(Path, 'tip_trajectory', RELIABLE_QOS)
    task_pub = probe.create_publisher(String, 'control_task', RELIABLE_QOS)
    executor.add_node(probe)

    for node in ('load_estimator', 'elastostatic_ik'):
        node_processes.start('inflarm_control' if node == 'elastostatic_ik'
                             else 'inflarm_estimation', node, '--params-file', arm_yaml,
                             parameters=UNDER_TEST)
    node_processes.start('inflarm_hw', 'arm_sim', '--params-file', arm_yaml,
                         parameters={'seed': 7})
    # The ball position from sra_sim's stand-in measurement (no camera and ball_tracker: they
    # are not under test, and rendering would load the machine) at 20 Hz; the controller at
    # 5 Hz (its installed rate).
    node_processes.start('inflarm_hw', 'sra_sim', parameters={
        'seed': 7, 'camera.enabled': False, 'publish_ball_position': True,
        'camera_rate_hz': 20.0})
    node_processes.start('inflarm_control', 'pressure_controller', '--params-file',
                         str(params_file), parameters=UNDER_TEST)
    node_processes.start('inflarm_hw', 'bag_recorder', parameters={
        'topics': INPUTS + OUTPUTS + [RECORDS], 'output': str(bag)})
    # Every publisher matched by the recorder: each is matched on its own, a second or more
    # after its topic was found when the machine is busy, and the records and messages of one
    # matched after the path was sent are lost from the bag (the replayed IK then has no load
    # when the path comes and rejects it).
    for topic in INPUTS + OUTPUTS + [RECORDS]:
        count = '3 publishers' if topic == RECORDS else '1 publisher'  # the nodes under test
        assert node_processes.wait_for_output(
            f'[bag_recorder]: /{topic}: recording from {count}', 30.0), node_processes.output()
    # The IK and the controller hear the probe (and so does the recorder).
    assert spin_until(executor, lambda: path_pub.get_subscription_count() == 2
                      and task_pub.get_subscription_count() == 2, timeout_s=15.0)
    # A second of estimates from here, all in the bag (the IK's load before the path; the
    # regression's start-up): when the recorder matched late, the probe has had its own for
    # long.
    received = len(wrenches)
    assert spin_until(executor, lambda: tips and len(wrenches) >= received + 50,
                      timeout_s=20.0), node_processes.output()

    # A 2 s path from where the tip is, due 0.5 s after it is sent (as tip_path_demo does).
    start = np.array([tips[-1].point.x, tips[-1].point.y, tips[-1].point.z])
    due = probe.get_clock().now() + Duration(seconds=0.5)
    path = Path()
    path.header.stamp, path.header.frame_id = due.to_msg(), 'base_link'
    for t in np.linspace(0.0, 2.0, 20):
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = (due + Duration(seconds=t)).to_msg(), 'base_link'
        point = start + t / 2.0 * np.array([-0.03, 0.08, -0.03])
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = point.tolist()
        pose.pose.orientation.w = 1.0
        path.poses.append(pose)
    path_pub.publish(path)
    commands_before = len(commands)
    task_pub.publish(to_string_msg(ControlTask(frame_id='sra_mount', target=TARGET, mode='pid',
                                               trial_id=0)))
    assert spin_until(executor, lambda: reports and len(commands) > commands_before + 100,
                      timeout_s=TRIAL_S + 15.0), node_processes.output()
    spin_until(executor, lambda: False, timeout_s=0.5)  # the held commands after the trial
    # The recorder stops last, once the others have: a message or a callback record still in
    # flight when it stopped would leave a record without its message, or an output without
    # the record of the callback that published it.
    for name in ('arm_sim', 'sra_sim', 'load_estimator', 'elastostatic_ik',
                 'pressure_controller'):
        assert _stop(node_processes.group.processes[name]) == 0, node_processes.output()
    spin_until(executor, lambda: False, timeout_s=0.5)
    assert _stop(node_processes.group.processes['bag_recorder']) == 0, node_processes.output()
    executor.remove_node(probe)
    probe.destroy_node()


@pytest.fixture(scope='module')
def recorded(tmp_path_factory) -> tuple[pathlib.Path, pathlib.Path]:
    """(bag, parameter file) of the simulated run, recorded once per module whichever test
    comes first or runs alone: on a domain, context and processes of its own, all stopped
    (exit codes 0) before any test reads it. The tests only read the two files."""
    root = tmp_path_factory.mktemp('regression')
    params_file = root / 'run_parameters.yaml'
    params_file.write_text(yaml.safe_dump(
        {node: {'ros__parameters': values} for node, values in RUN_PARAMETERS.items()}))
    domain, lock = lock_free_domain()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    executor = SingleThreadedExecutor(context=context)
    processes = NodeProcesses(domain, root)
    try:
        record_run(processes, executor, root / 'run', params_file)
    finally:
        codes = processes.stop()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
        lock.close()
    assert all(code == 0 for code in codes.values()), (
        f'unclean exit codes {codes}; output:\n{processes.output()}')
    return root / 'run', params_file


def test_the_recorded_run_replays_exactly(recorded, tmp_path, capsys):
    bag, params_file = recorded
    info = bag_info(bag)
    assert {f'/{t}' for t in INPUTS + OUTPUTS + [RECORDS]} <= set(info.topics), info.topics
    out = tmp_path / 'out'
    code = main([str(bag), '--params-file', str(params_file), '--out', str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert 'nodes under test: load_estimator, elastostatic_ik, pressure_controller' in printed
    assert f'PASS: {len(OUTPUTS)} topics within tolerance' in printed
    replayed = bag_info(out / 'replayed')
    for topic in OUTPUTS:
        assert replayed.topics[f'/{topic}'].message_count > 0, topic
    report_md = (out / 'report.md').read_text().splitlines()
    assert sum(line.endswith(' ok') for line in report_md) >= len(OUTPUTS), report_md
    assert f'PASS: {len(OUTPUTS)} topics within tolerance' in report_md
    assert (out / 'report.csv').read_text().startswith('topic,type,key,recorded')
    # Every callback ran, but for messages a node took before the recorder's subscription to
    # their topic was matched (the recorder subscribes to each topic as it discovers it).
    result = replay(bag, params_files=[params_file])
    assert all(ran > 100 for ran in result.callbacks.values()), result.callbacks
    first = {t: next(read_messages(bag, [t])).timestamp_ns for t in info.topics}
    late = [(n, r) for n, r in result.skipped if r.time_ns > first[r.callback] + 0.5e9]
    assert not late, late
    # After the start-up, every recorded output has its replayed twin, one for one, equal to
    # rounding: the nodes computed them from the same messages at the same clock readings.
    report = regression(bag, result)
    for topic in report.topics:
        assert topic.matched == topic.recorded > 0, topic
        assert all(f.max_abs_diff <= 1e-9 for f in topic.fields), topic
    wrench = next(t for t in report.topics if t.topic == '/estimated_wrench')
    assert wrench.key == 'stamp' and wrench.matched > 100
    trial = next(t for t in report.topics if t.topic == '/trial_report')
    assert trial.recorded == trial.replayed == trial.matched == 1


def test_two_replays_give_identical_outputs(recorded):
    bag, params_file = recorded
    first = replay(bag, params_files=[params_file])
    second = replay(bag, params_files=[params_file])
    assert len(first.outputs) > 500
    assert first.outputs == second.outputs  # topics, times and CDR bytes
    assert first.inputs == second.inputs and first.callbacks == second.callbacks


def test_a_record_whose_message_the_recorder_lost_is_skipped_and_counted(recorded, tmp_path,
                                                                        capsys):
    bag, params_file = recorded
    info = bag_info(bag)
    # two samples whose estimates the bag holds (an estimate has its sample's stamp)
    estimated = [stamp_ns(deserialize(m.data, m.msgtype))
                 for m in read_messages(bag, ['/estimated_wrench'])]
    lost = set(estimated[len(estimated) // 2:len(estimated) // 2 + 2])
    lossy = tmp_path / 'lossy'
    with BagWriter(lossy) as writer:
        for topic, topic_info in sorted(info.topics.items()):
            writer.add_topic(topic, topic_info.msgtype, topic_info.offered_qos)
        for m in read_messages(bag, sorted(info.topics)):
            if not (m.topic == '/joint_states'
                    and stamp_ns(deserialize(m.data, m.msgtype)) in lost):
                writer.write(m.topic, m.timestamp_ns, m.data)
    skipped = len(replay(bag, ['load_estimator'], [params_file]).skipped)
    result = replay(lossy, ['load_estimator'], [params_file])
    assert len(result.skipped) == skipped + 2
    # The estimator took those two samples fewer: their estimates are missing, every other
    # one is replayed exactly.
    report = regression(lossy, result)
    for name in ('/estimated_wrench', '/estimated_joint_states', '/estimated_tip'):
        topic = next(t for t in report.topics if t.topic == name)
        assert topic.matched == topic.recorded - 2, topic
        assert all(f.max_abs_diff <= f.tolerance for f in topic.fields), topic
    main([str(lossy), '--nodes', 'load_estimator', '--params-file', str(params_file)])
    assert f'load_estimator {result.callbacks["load_estimator"]} ({skipped + 2} skipped: ' \
        'message not recorded)' in capsys.readouterr().out


def test_outputs_the_recorder_took_late_are_compared_with_those_of_their_own_callback(
        recorded, tmp_path):
    # On a busy machine the recorder takes a message tens of ms after it was published: more
    # than half the spacing of link_status (10 Hz per link), so that by receive time a status
    # would be paired with the next callback's. Each is timed at the callback that published
    # it, which its record lists.
    bag, params_file = recorded
    late = tmp_path / 'late'
    info = bag_info(bag)
    with BagWriter(late) as writer:
        for topic, topic_info in sorted(info.topics.items()):
            writer.add_topic(topic, topic_info.msgtype, topic_info.offered_qos)
        for m in read_messages(bag, sorted(info.topics)):
            delay = 70_000_000 if m.topic in ('/link_status', '/chamber_pressure_command') else 0
            writer.write(m.topic, m.timestamp_ns + delay, m.data)
    report = regression(late, replay(late, ['load_estimator', 'pressure_controller'],
                                     [params_file]))
    for name in ('/link_status', '/chamber_pressure_command'):
        topic = next(t for t in report.topics if t.topic == name)
        assert topic.key == 'time' and topic.matched == topic.recorded > 20, topic
        assert all(f.max_abs_diff <= 1e-9 for f in topic.fields), topic


def test_a_callback_record_names_the_messages_its_callback_published(executor):
    from rclpy.node import Node

    from inflarm_msgs_json.ros.node import CALLBACK_LOG_QOS, GuardedCallbacks

    class Echo(GuardedCallbacks, Node):
        def __init__(self, **kwargs) -> None:
            super().__init__('echo', **kwargs)
            self.text_pub = self.create_publisher(String, 'echo_text', RELIABLE_QOS)
            self.point_pub = self.create_publisher(PointStamped, 'echo_point', RELIABLE_QOS)
            self.create_guarded_subscription(String, 'text', self.on_text, RELIABLE_QOS)

        def on_text(self, msg: String) -> None:
            point = PointStamped()
            point.header.stamp.sec = 12
            self.point_pub.publish(point)
            self.text_pub.publish(String(data=msg.data.upper()))
            self.text_pub.publish(b'raw bytes: no stamp, no text')

    echo = Echo(context=executor.context, parameter_overrides=[
        rclpy.parameter.Parameter('callback_log', value=True)])
    probe = rclpy.create_node('probe', context=executor.context)
    records: list = []
    probe.create_subscription(String, '/callback_log', lambda m: records.append(decode(m.data)),
                              CALLBACK_LOG_QOS)
    text_pub = probe.create_publisher(String, 'text', RELIABLE_QOS)
    for node in (echo, probe):
        executor.add_node(node)
    [log_pub] = [p for p in echo.publishers if p.topic_name == '/callback_log']
    assert spin_until(executor, lambda: text_pub.get_subscription_count() == 1
                      and log_pub.get_subscription_count() == 1)
    text_pub.publish(String(data='hello'))
    assert spin_until(executor, lambda: records)
    [record] = records
    assert record.callback == '/text' and record.digest == zlib.crc32(b'hello')
    assert [(m.topic, m.stamp_ns, m.digest) for m in record.published] == [
        ('/echo_point', 12_000_000_000, None), ('/echo_text', None, zlib.crc32(b'HELLO'))]
    # Outside a callback (a background job's thread, the node's start): no record lists it.
    echo.text_pub.publish(String(data='unlisted'))
    text_pub.publish(String(data='again'))
    assert spin_until(executor, lambda: len(records) == 2)
    assert [(m.topic, m.digest) for m in records[1].published] == [
        ('/echo_point', None), ('/echo_text', zlib.crc32(b'AGAIN'))]


def test_a_changed_spring_stiffness_fails_naming_the_topics(recorded, tmp_path, capsys):
    bag, params_file = recorded
    stiffer = tmp_path / 'stiffer.yaml'
    stiffer.write_text(yaml.safe_dump({'load_estimator': {'ros__parameters': {
        'arm.spring_stiffness': [190.0, 190.0, 190.0, 190.0]}}}))
    code = main([str(bag), '--nodes', 'load_estimator', '--params-file', str(params_file),
                 str(stiffer)])
    printed = capsys.readouterr().out
    assert code == 1, printed
    assert 'FAIL /estimated_wrench: wrench.force differs by' in printed
    assert 'FAIL /estimated_joint_states: position differs by' in printed
    assert 'FAIL /link_status:' in printed
    assert 'nodes under test: load_estimator\n' in printed


def test_a_changed_ik_stiffness_fails_on_the_motor_commands(recorded, tmp_path, capsys):
    # A 10 % stiffer IK model (x 0.9 makes the path unreachable: the IK rejects it); the IK
    # alone, on the recorded estimates.
    bag, params_file = recorded
    stiffness = [1.1 * k for k in _installed_arm_parameters()['arm.spring_stiffness']]
    stiffer = tmp_path / 'stiffer_ik.yaml'
    stiffer.write_text(yaml.safe_dump({'elastostatic_ik': {'ros__parameters': {
        'arm.spring_stiffness': stiffness}}}))
    code = main([str(bag), '--nodes', 'elastostatic_ik', '--params-file', str(params_file),
                 str(stiffer)])
    printed = capsys.readouterr().out
    assert code == 1, printed
    assert 'FAIL: /motor_position_command out of tolerance' in printed  # that topic alone
    assert 'nodes under test: elastostatic_ik\n' in printed
    result = replay(bag, ['elastostatic_ik'], [params_file, stiffer])
    report = compare(read_messages(bag, ['/motor_position_command']), result.outputs,
                     topics=['/motor_position_command'])
    position = next(f for f in report.topics[0].fields if f.group == 'position')
    assert position.max_abs_diff > 10 * DEFAULT_TOLERANCES.of('/motor_position_command',
                                                              'position'), position


def _installed_arm_parameters() -> dict:
    from ament_index_python.packages import get_package_share_directory
    arm_yaml = pathlib.Path(get_package_share_directory(ARM_CONFIG[0]), 'config', ARM_CONFIG[1])
    return yaml.safe_load(arm_yaml.read_text())['/**']['ros__parameters']


def test_a_bag_without_callback_records_is_rejected_with_what_is_missing(recorded, tmp_path,
                                                                        capsys):
    bag = tmp_path / 'truth_only'
    with BagWriter(bag) as writer:
        writer.add_topic('/tip_position_truth', 'geometry_msgs/msg/PointStamped')
    assert main([str(bag)]) == 2
    err = capsys.readouterr().err
    assert 'the bag holds no /callback_log' in err and 'callback_log true' in err

    recorded_bag, _ = recorded
    assert main([str(recorded_bag), '--nodes', 'load_estimator', '--params-file',
                 str(tmp_path / 'none.yaml')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    assert main([str(tmp_path / 'missing')]) == 2
    assert 'no bag at' in capsys.readouterr().err
    assert main([str(bag), '--nodes', 'load_estimator,planner']) == 2
    assert '--nodes: expected names of' in capsys.readouterr().err
    assert main([str(bag), '--tolerance', 'force:0.1']) == 2
    assert 'expected [TOPIC:]QUANTITY=VALUE' in capsys.readouterr().err


def _with_records(bag: pathlib.Path, out: pathlib.Path, change) -> pathlib.Path:
    """``bag`` copied to ``out`` with its first ``/callback_log`` text replaced by
    ``change(text)``."""
    info = bag_info(bag)
    string = typestore().types['std_msgs/msg/String']
    changed = False
    with BagWriter(out) as writer:
        for topic, topic_info in sorted(info.topics.items()):
            writer.add_topic(topic, topic_info.msgtype, topic_info.offered_qos)
        for m in read_messages(bag, sorted(info.topics)):
            data = m.data
            if m.topic == '/callback_log' and not changed:
                text = typestore().deserialize_cdr(m.data, m.msgtype).data
                data, changed = serialize(string(data=change(text)), m.msgtype), True
            writer.write(m.topic, m.timestamp_ns, data)
    return out


def test_a_malformed_or_unknown_callback_record_is_rejected_naming_it(recorded, tmp_path,
                                                                     capsys):
    bag, params_file = recorded
    torn = _with_records(bag, tmp_path / 'torn', lambda text: text[:len(text) // 2])
    assert main([str(torn), '--params-file', str(params_file)]) == 2
    err = capsys.readouterr().err
    assert '/callback_log at ' in err and ' ns: ' in err

    renamed = _with_records(bag, tmp_path / 'renamed', lambda text: encode(
        dataclasses.replace(decode(text), callback='timer nope')))
    assert main([str(renamed), '--params-file', str(params_file)]) == 2
    assert "has no callbacks ['timer nope'] that the bag records" in capsys.readouterr().err


def test_replayed_messages_are_canonical_cdr():
    # serialize_message's bytes of a JointState with an empty sequence run 8 bytes long, which
    # rosbags refuses; the replay's are those rosbags writes for the same values.
    from inflarm_bringup.ros.lockstep import to_cdr
    joints = JointState(name=['m1', 'm2'], position=[0.5, -1.25], effort=[2.0])
    joints.header.stamp.sec, joints.header.frame_id = 7, 'base_link'
    expected = serialize(typestore().types['sensor_msgs/msg/JointState'](
        header=typestore().types['std_msgs/msg/Header'](
            stamp=typestore().types['builtin_interfaces/msg/Time'](sec=7, nanosec=0),
            frame_id='base_link'),
        name=['m1', 'm2'], position=np.array([0.5, -1.25]), velocity=np.array([]),
        effort=np.array([2.0])), 'sensor_msgs/msg/JointState')
    assert to_cdr(joints) == expected
    text = String(data='{"type": "TrialReport"}')
    assert to_cdr(text) == serialize(typestore().types['std_msgs/msg/String'](
        data=text.data), 'std_msgs/msg/String')
