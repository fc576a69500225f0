"""elastostatic_ik in-process: targets and trajectories to motor commands; rejections."""

from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from inflarm_control.nodes.elastostatic_ik import ElastostaticIk, resample
from inflarm_model.elastostatics import spring_deflections
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS
from inflarm_msgs_json.ros.qos import COMMAND_QOS, JOINT_STATE_QOS, RELIABLE_QOS
from ros_harness import spin_until

ARM = FlexibleArm(0.6, 0.03)
FORCE = np.array([0.0, 10.0, -15.0])
Q_M = [0.0, 0.6, -1.2]


def deflected_tip(q_m, force=FORCE) -> np.ndarray:
    return spring_deflections(ARM, q_m, force, MEAN_STIFFNESS).tip_position


class Rig:
    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.node = ElastostaticIk(context=executor.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.commands: list[JointState] = []
        self.probe.create_subscription(JointState, 'motor_position_command',
                                       self.commands.append, COMMAND_QOS)
        self.target_pub = self.probe.create_publisher(PointStamped, 'tip_target', COMMAND_QOS)
        self.path_pub = self.probe.create_publisher(Path, 'tip_trajectory', RELIABLE_QOS)
        self.joint_pub = self.probe.create_publisher(JointState, 'joint_states', JOINT_STATE_QOS)
        self.pose_pub = self.probe.create_publisher(JointState, 'estimated_joint_states',
                                                    JOINT_STATE_QOS)
        self.wrench_pub = self.probe.create_publisher(WrenchStamped, 'estimated_wrench',
                                                      RELIABLE_QOS)
        executor.add_node(self.node)
        executor.add_node(self.probe)
        assert spin_until(executor, lambda: self.target_pub.get_subscription_count() == 1
                          and self.wrench_pub.get_subscription_count() == 1)

    def joints(self, q_m=Q_M) -> None:
        self.joint_pub.publish(JointState(name=['joint_1', 'joint_2', 'joint_3'],
                                          position=list(q_m)))
        assert spin_until(self.executor, lambda: self.node.q_m is not None)

    def target(self, point, frame_id='base_link') -> None:
        msg = PointStamped()
        msg.header.frame_id = frame_id
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in point)
        self.target_pub.publish(msg)

    def idle(self, seconds: float = 0.4) -> None:
        spin_until(self.executor, lambda: False, timeout_s=seconds)


def test_a_target_is_reached_by_the_deflected_arm(executor):
    rig = Rig(executor, **{'load.source': 'configured'})
    rig.joints()
    target = np.array([0.8, 0.2, 0.1])
    rig.target(target)
    assert spin_until(executor, lambda: rig.commands)
    assert list(rig.commands[0].name) == ['joint_1', 'joint_2', 'joint_3']
    q_m = np.array(rig.commands[0].position)
    assert np.linalg.norm(deflected_tip(q_m) - target) < 1e-7
    # the rigid arm would need other angles: the command compensates the deflection
    assert np.linalg.norm(deflected_tip(q_m, np.zeros(3)) - target) > 5e-3


def test_the_estimated_load_is_used_once_there_is_one(executor):
    rig = Rig(executor)
    rig.joints()
    rig.target([0.8, 0.2, 0.1])
    rig.idle()
    assert rig.commands == []  # no estimated_wrench yet: rejected
    wrench = WrenchStamped()
    wrench.header.frame_id = 'base_link'
    wrench.wrench.force.y, wrench.wrench.force.z = 5.0, -5.0
    rig.wrench_pub.publish(wrench)
    assert spin_until(executor, lambda: rig.node.estimated_force is not None)
    rig.target([0.8, 0.2, 0.1])
    assert spin_until(executor, lambda: rig.commands)
    tip = deflected_tip(rig.commands[0].position, [0.0, 5.0, -5.0])
    np.testing.assert_allclose(tip, [0.8, 0.2, 0.1], atol=1e-7)


def test_a_tip_frame_wrench_is_turned_into_the_base_frame_with_its_pose(executor):
    rig = Rig(executor)
    q = FlexibleArm.assemble_q(Q_M, [0.01, -0.02, 0.03, 0.01])
    stamp = rig.node.get_clock().now().to_msg()
    wrench = WrenchStamped()
    wrench.header.frame_id, wrench.header.stamp = 'tip', stamp
    force_tip = ARM.fk(q)[:3, :3].T @ FORCE
    wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = force_tip.tolist()
    rig.wrench_pub.publish(wrench)  # before its pose: kept until the pose comes
    rig.idle(0.3)
    assert rig.node.estimated_force is None
    pose = JointState(name=list(FlexibleArm.JOINT_NAMES), position=q.tolist())
    pose.header.stamp = stamp
    rig.pose_pub.publish(pose)
    assert spin_until(executor, lambda: rig.node.estimated_force is not None)
    np.testing.assert_allclose(rig.node.estimated_force, FORCE, atol=1e-9)
    wrench.header.frame_id = 'camera'
    rig.wrench_pub.publish(wrench)
    rig.idle(0.3)
    assert "frame_id 'camera'" in rig.node.problems.last['estimated_wrench']


def test_bad_targets_are_rejected_and_the_node_keeps_going(executor):
    rig = Rig(executor, **{'load.source': 'configured'})
    rig.target([0.8, 0.2, 0.1])  # no joint states yet
    rig.joints()
    rig.target([2.0, 0.0, 0.0])  # beyond 2L
    rig.target([0.8, 0.2, 0.1], frame_id='camera')  # wrong frame
    rig.idle()
    assert rig.commands == []
    rig.target([0.8, 0.2, 0.1])
    assert spin_until(executor, lambda: rig.commands)


def path_msg(points, times, start) -> Path:
    path = Path()
    path.header.frame_id = 'base_link'
    for point, t in zip(points, times, strict=True):
        pose = PoseStamped()
        pose.header.stamp = (start + Duration(seconds=float(t))).to_msg()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
            float(v) for v in point)
        path.poses.append(pose)
    return path


def test_a_trajectory_is_streamed_and_ends_on_its_last_point(executor):
    rig = Rig(executor, **{'load.source': 'configured'})
    start_q = [0.0, 0.6, -1.2]
    rig.joints(start_q)
    first = deflected_tip(start_q)
    goal = first + [-0.1, 0.1, 0.05]
    times = np.linspace(0.0, 1.0, 11)
    points = first + np.outer(times, goal - first)
    rig.path_pub.publish(path_msg(points, times, rig.node.get_clock().now()))
    assert spin_until(executor, lambda: rig.node.trajectory is not None)
    assert spin_until(executor, lambda: rig.node.trajectory is None, timeout_s=5.0)
    rig.idle()  # the last set point is on its way
    assert len(rig.commands) > 10
    assert np.linalg.norm(deflected_tip(rig.commands[-1].position) - goal) < 1e-3


def test_a_trajectory_without_increasing_stamps_is_rejected(executor):
    rig = Rig(executor, **{'load.source': 'configured'})
    rig.joints()
    now = rig.node.get_clock().now()
    rig.path_pub.publish(path_msg([[0.8, 0.0, 0.0], [0.8, 0.1, 0.0]], [0.0, 0.0], now))
    rig.idle()
    assert rig.node.trajectory is None and rig.commands == []


def test_a_path_out_of_reach_or_too_long_is_rejected_whole(executor):
    rig = Rig(executor, **{'load.source': 'configured', 'max_duration_s': 60.0})
    rig.joints()
    first = deflected_tip(Q_M)
    now = rig.node.get_clock().now()
    # Through (5, 5, 5) m: far beyond 2L; the integrated motors would run away.
    rig.path_pub.publish(path_msg([first, [5.0, 5.0, 5.0]], [0.0, 2.0], now))
    assert spin_until(executor, lambda: 'tip_trajectory' in rig.node.problems.last)
    assert rig.commands == [] and rig.node.trajectory is None
    assert 'tip strays' in rig.node.problems.last['tip_trajectory'] \
        or 'outside its limits' in rig.node.problems.last['tip_trajectory']
    # Two poses 1e4 s apart: bounded before anything is resampled or integrated.
    rig.path_pub.publish(path_msg([first, first + 0.01], [0.0, 1e4], now))
    rig.idle()
    assert rig.commands == []
    assert 'over max_duration_s' in rig.node.problems.last['tip_trajectory']
    assert rig.node.problems.unexpected == 0

def test_the_set_point_streams_on_while_a_long_trajectory_is_integrated(executor):
    # the longest path accepted (600 s, 12,000 steps of eq. 9) takes about a second here: on
    # the executor it would stop the stream, and a motor watchdog would hold the arm
    rig = Rig(executor, **{'load.source': 'configured'})
    rig.joints()
    first = deflected_tip(Q_M)
    rig.target(first)
    assert spin_until(executor, lambda: rig.commands)
    times = np.linspace(0.0, 600.0, 61)
    points = first + np.outer(times / 600.0, [-0.05, 0.05, 0.02])
    rig.path_pub.publish(path_msg(points, times, rclpy.time.Time()))
    assert spin_until(executor, lambda: rig.node.worker.busy, timeout_s=5.0)
    during = len(rig.commands)
    assert spin_until(executor, lambda: not rig.node.worker.busy, timeout_s=60.0)
    streamed = len(rig.commands) - during
    assert spin_until(executor, lambda: rig.node.trajectory is not None)
    assert streamed >= 5, f'{streamed} set points streamed while integrating'
    # a newer command overtakes a trajectory still being integrated: it is dropped
    rig.path_pub.publish(path_msg(points, times, rclpy.time.Time()))
    assert spin_until(executor, lambda: rig.node.worker.busy, timeout_s=5.0)
    rig.target(first)
    assert spin_until(executor, lambda: not rig.node.worker.busy, timeout_s=60.0)
    rig.idle()
    assert rig.node.trajectory is None
    np.testing.assert_allclose(deflected_tip(rig.commands[-1].position), first, atol=1e-4)
    assert rig.node.problems.unexpected == 0


def test_resample_keeps_the_waypoints_and_bounds_the_step():
    times = np.array([0.0, 1.0, 1.5])
    x_d = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [1.0, 2.0, 4.0]])
    fine, x_fine = resample(times, x_d, 0.3)
    assert np.diff(fine).max() <= 0.3 + 1e-12
    for t, x in zip(times, x_d, strict=True):
        np.testing.assert_allclose(x_fine[np.argmin(np.abs(fine - t))], x)


def test_a_late_trajectory_is_joined_where_it_is_due_and_relative_stamps_start_now(executor):
    rig = Rig(executor, **{'load.source': 'configured'})
    rig.joints()
    first = deflected_tip(Q_M)
    times = np.linspace(0.0, 2.0, 21)
    points = first + np.outer(times, [-0.02, 0.02, 0.01])
    now = rig.node.get_clock().now()
    # Due 0.5 s ago: it runs on its stamps, not 0.5 s behind them.
    rig.path_pub.publish(path_msg(points, times, now - Duration(seconds=0.5)))
    assert spin_until(executor, lambda: rig.node.trajectory is not None)
    assert rig.node.trajectory_start_ns == (now - Duration(seconds=0.5)).nanoseconds
    assert spin_until(executor, lambda: rig.node.trajectory is None, timeout_s=5.0)
    # Ended before it arrived: rejected, naming why.
    rig.path_pub.publish(path_msg(points, times, now - Duration(seconds=10.0)))
    assert spin_until(executor, lambda: 'nothing of it is due'
                      in rig.node.problems.last.get('tip_trajectory', ''))
    # Stamped from 0: relative, it starts when it is solved.
    rig.path_pub.publish(path_msg(points, times, rclpy.time.Time()))
    assert spin_until(executor, lambda: rig.node.trajectory is not None)
    assert rig.node.trajectory_start_ns >= now.nanoseconds
    assert rig.node.problems.unexpected == 0
