"""pressure_controller in-process: task validation, vision dropout, learning memory, services."""

from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_control.nodes.pressure_controller import PressureController
from inflarm_msgs_json import ControlTask, PressureCommand, TrialReport, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import COMMAND_QOS, RELIABLE_QOS, SENSOR_QOS
from ros_harness import spin_until

START = (0.0, 0.0, 0.604)
TARGET = (0.100, 0.110, 0.670)


class Rig:
    """The controller plus a probe node standing in for the camera and the valves."""

    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.controller = PressureController(
            context=executor.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.commands: list[PressureCommand] = []
        self.reports: list[TrialReport] = []
        self.probe.create_subscription(
            String, 'chamber_pressure_command',
            lambda m: self.commands.append(decode(m.data)), COMMAND_QOS)
        self.probe.create_subscription(
            String, 'trial_report', lambda m: self.reports.append(decode(m.data)), RELIABLE_QOS)
        self.ball_pub = self.probe.create_publisher(PointStamped, 'ball_position', SENSOR_QOS)
        self.task_pub = self.probe.create_publisher(String, 'control_task', RELIABLE_QOS)
        executor.add_node(self.controller)
        executor.add_node(self.probe)
        assert spin_until(executor, lambda: self.task_pub.get_subscription_count() == 1)

    def ball(self, point, frame_id='sra_mount') -> None:
        msg = PointStamped()
        msg.header.frame_id = frame_id
        msg.point.x, msg.point.y, msg.point.z = point
        self.ball_pub.publish(msg)

    def task(self, target, mode='pid', trial_id=0) -> None:
        self.task_pub.publish(to_string_msg(
            ControlTask(frame_id='sra_mount', target=target, mode=mode, trial_id=trial_id)))

    def spin(self, seconds: float) -> None:
        spin_until(self.executor, lambda: False, timeout_s=seconds)

    def call(self, service: str) -> Trigger.Response:
        client = self.probe.create_client(Trigger, f'/pressure_controller/{service}')
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(Trigger.Request())
        self.executor.spin_until_future_complete(future, timeout_sec=5.0)
        return future.result()


def test_defaults_and_read_only_gains(executor):
    rig = Rig(executor)
    node = rig.controller
    assert node.get_parameter('rate_hz').value == 5.0
    assert node.get_parameter('quadrant_bellows').value == ['B4,B3', 'B2,B3', 'B2,B1', 'B4,B1']
    assert node.get_parameter('path.bellows_preload_pa').value == 6000.0
    assert node.get_parameter('path.speed_mps').value == 0.003
    assert node.get_parameter('path.feedforward_lead_s').value == 2.5
    assert not node.set_parameters([Parameter('gains.kp', value=[1.0, 1.0, 1.0])])[0].successful
    assert not node.set_parameters([Parameter('trial_duration_s', value=0.0)])[0].successful


def test_tasks_are_rejected_without_a_position_or_outside_the_workspace(executor):
    rig = Rig(executor)
    rig.task(TARGET)  # no ball position yet
    rig.spin(0.5)
    assert not rig.controller.session.trial_active and rig.commands == []

    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    rig.task((0.1, 0.1, 1.2))  # above the workspace
    rig.spin(0.5)
    assert not rig.controller.session.trial_active and rig.commands == []

    rig.ball((np.nan, 0.0, 0.6))  # ignored: the last good position stays
    rig.ball((0.0, 0.0, 0.7), frame_id='camera')  # ignored: wrong frame
    rig.spin(0.3)
    np.testing.assert_array_equal(rig.controller.session.position, START)

    rig.task(TARGET)  # the node kept running and accepts a valid task
    assert spin_until(executor, lambda: len(rig.commands) >= 2)
    assert rig.controller.session.trial_active


def test_a_vision_dropout_holds_the_pressures_and_records_no_learning(executor):
    rig = Rig(executor, measurement_timeout_s=0.3)
    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    rig.task(TARGET)
    # With the ball far from the target, PID raises the pressures step by step...
    for _ in range(6):
        rig.ball(START)
        rig.spin(0.2)
    assert rig.commands[-1].as_dict()['PEA'] > rig.commands[0].as_dict()['PEA']
    # ...then the camera goes silent: after the timeout every command repeats the last one.
    rig.spin(0.5)
    held = rig.commands[-1]
    count = len(rig.commands)
    rig.spin(1.0)
    assert len(rig.commands) >= count + 3
    assert all(c == held for c in rig.commands[count:])


def test_a_finished_trial_reports_learns_and_seeds_the_next(executor, tmp_path):
    memory_file = tmp_path / 'ilc.npz'
    rig = Rig(executor, trial_duration_s=1.0, ilc_memory_path=str(memory_file))
    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    rig.task(TARGET, mode='pid_ilc', trial_id=0)

    def keep_seeing_start():
        rig.ball(START)
        return bool(rig.reports)
    assert spin_until(executor, keep_seeing_start, timeout_s=10.0)
    report = rig.reports[0]
    assert report.trial_index == 0
    # The ball never moved: the error stayed the full distance on every axis.
    np.testing.assert_allclose(report.rmse, np.abs(np.subtract(START, TARGET)), rtol=1e-9)
    assert report.reach_time == (None, None, None)
    assert memory_file.exists()

    response = rig.call('start_trial')
    assert response.success and 'trial 1' in response.message
    # Trial 1 starts from trial 0's recorded outputs, not from zero.
    assert rig.controller.session.controller._ff[0, 0].max() > 0.0

    assert rig.call('reset_learning').message == 'forgot 1 ILC memories'
    assert rig.call('stop').success
    assert not rig.controller.session.trial_active


def test_a_corrupt_memory_file_stops_the_node_at_startup(ros_context, tmp_path):
    bad = tmp_path / 'bad.npz'
    bad.write_bytes(b'not an npz file')
    with pytest.raises(ValueError, match='is not an ILC memory file'):
        PressureController(context=ros_context,
                           parameter_overrides=[Parameter('ilc_memory_path', value=str(bad))])


def test_vent_ends_the_trial_and_holds_zero_pressure(executor):
    rig = Rig(executor)
    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    rig.task(TARGET)
    assert spin_until(executor, lambda: len(rig.commands) >= 3)
    assert rig.call('vent').success
    assert not rig.controller.session.trial_active
    count = len(rig.commands)
    rig.spin(0.7)
    assert len(rig.commands) >= count + 2
    assert all(set(c.as_dict().values()) == {0.0} for c in rig.commands[count:])


def test_a_planned_path_is_followed_at_the_arms_pace_with_preloaded_bellows(executor):
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path

    from inflarm_msgs_json.ros.qos import LATCHED_QOS

    rig = Rig(executor, **{'path.speed_mps': 0.05})
    path_pub = rig.probe.create_publisher(Path, 'planned_path', LATCHED_QOS)
    waypoints = [(0.02, 0.02, 0.62), (0.05, 0.05, 0.64), TARGET]
    rig.ball(waypoints[0])
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    path = Path()
    path.header.frame_id = 'sra_mount'
    for point in waypoints:
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = point
        path.poses.append(pose)
    path_pub.publish(path)
    assert spin_until(executor, lambda: rig.controller.session.following)
    follower = rig.controller.session.follower
    np.testing.assert_allclose(follower.goal, TARGET)
    rig.ball((0.02, 0.02, 0.66))  # 40 mm off the reference: it waits
    rig.spin(0.6)
    assert follower.progress < 0.01

    def ball_follows():
        rig.ball(follower.reference)  # the camera sees the ball where it is asked to be
        return follower.at_end
    assert spin_until(executor, ball_follows, timeout_s=10.0)
    assert rig.commands and all(
        min(c.as_dict()[b] for b in ('B1', 'B2', 'B3', 'B4')) >= 6000.0
        for c in rig.commands)
    rig.task(TARGET)  # a task ends the path
    assert spin_until(executor, lambda: rig.controller.session.trial_active)
    assert not rig.controller.session.following


def test_a_path_outside_the_workspace_is_rejected(executor):
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path

    from inflarm_msgs_json.ros.qos import LATCHED_QOS

    rig = Rig(executor)
    path_pub = rig.probe.create_publisher(Path, 'planned_path', LATCHED_QOS)
    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    path = Path()
    path.header.frame_id = 'sra_mount'
    for point in ((0.0, 0.0, 0.62), (0.0, 0.0, 1.5)):
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = point
        path.poses.append(pose)
    path_pub.publish(path)
    rig.spin(0.5)
    assert not rig.controller.session.trial_active and rig.commands == []


def test_an_absurd_ball_position_reaches_neither_the_report_nor_the_memory(executor, tmp_path):
    memory_file = tmp_path / 'ilc.npz'
    rig = Rig(executor, trial_duration_s=1.0, ilc_memory_path=str(memory_file))
    rig.ball(START)
    assert spin_until(executor, lambda: rig.controller.session.position is not None)
    rig.task(TARGET, mode='pid_ilc', trial_id=0)

    def camera_glitches():
        rig.ball((1e300, 0.0, 0.604))  # finite, absurd: rejected as a measurement
        rig.ball(START)
        return bool(rig.reports)
    assert spin_until(executor, camera_glitches, timeout_s=10.0)
    np.testing.assert_allclose(rig.reports[0].rmse, np.abs(np.subtract(START, TARGET)),
                               rtol=1e-9)
    assert 'above the workspace maximum' in rig.controller.problems.last['ball_position']
    with np.load(memory_file) as data:
        assert np.isfinite(data['memories']).all()
        assert data['memories'].max() <= 100e3


def test_obstacles_set_the_alert_regions_the_follower_repels_from(executor):
    from inflarm_msgs_json import Cuboid, ObstacleSet
    from inflarm_msgs_json.ros.qos import LATCHED_QOS

    rig = Rig(executor)
    node = rig.controller
    assert node.get_parameter('path.repulsion_gain').value == 1.0
    assert node.session.follower.params.repulsion_gain == 1.0
    assert not node.set_parameters([Parameter('path.repulsion_gain', value=2.0)])[0].successful
    obstacles_pub = rig.probe.create_publisher(String, 'obstacles', LATCHED_QOS)
    box = Cuboid(min=(0.035, 0.04, 0.65), max=(0.14, 0.14, 0.78), name='box')
    obstacles_pub.publish(to_string_msg(ObstacleSet('world', 0.03, (box,))))  # wrong frame
    rig.spin(0.3)
    assert node.session.follower.alert_regions.shape == (0, 2, 3)
    obstacles_pub.publish(to_string_msg(ObstacleSet('sra_mount', 0.03, (box,))))
    assert spin_until(executor, lambda: len(node.session.follower.alert_regions) == 1)
    np.testing.assert_allclose(node.session.follower.alert_regions[0],
                               [[0.005, 0.01, 0.62], [0.17, 0.17, 0.81]], atol=1e-12)


def test_a_repulsion_gain_out_of_range_stops_the_node_at_startup(ros_context):
    with pytest.raises(Exception, match='path.repulsion_gain'):
        PressureController(context=ros_context,
                           parameter_overrides=[Parameter('path.repulsion_gain', value=-1.0)])
