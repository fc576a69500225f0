"""tip_path_demo in-process: timed straight paths, alternating, starting from the true tip."""

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time

from inflarm_control.nodes.tip_path_demo import TipPathDemo
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from ros_harness import spin_until


def points(path: Path) -> np.ndarray:
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in path.poses])


def test_paths_alternate_between_the_ends_with_increasing_stamps(executor):
    demo = TipPathDemo(context=executor.context, parameter_overrides=[
        Parameter('duration_s', value=0.4), Parameter('pause_s', value=0.1),
        Parameter('samples', value=5)])
    probe = rclpy.create_node('probe', context=executor.context)
    paths: list[Path] = []
    probe.create_subscription(Path, 'tip_trajectory', paths.append, RELIABLE_QOS)
    truth_pub = probe.create_publisher(PointStamped, 'tip_position_truth', SENSOR_QOS)
    executor.add_node(demo)
    executor.add_node(probe)
    tip = PointStamped()
    tip.point.x, tip.point.y, tip.point.z = 0.95, 0.0, 0.0

    def more_paths():
        truth_pub.publish(tip)
        return len(paths) >= 3
    assert spin_until(executor, more_paths, timeout_s=10.0)

    start, goal = np.array([0.9, -0.2, 0.1]), np.array([0.7, 0.3, -0.1])
    first = points(paths[0])
    np.testing.assert_allclose(first[0], [0.95, 0.0, 0.0])  # from the true tip
    np.testing.assert_allclose(first[-1], goal)
    np.testing.assert_allclose(points(paths[1])[[0, -1]], [goal, start])
    np.testing.assert_allclose(points(paths[2])[[0, -1]], [start, goal])
    stamps = [Time.from_msg(p.header.stamp).nanoseconds for p in paths[1].poses]
    assert len(stamps) == 5 and np.all(np.diff(stamps) > 0)
    assert (stamps[-1] - stamps[0]) * 1e-9 == pytest.approx(0.4)
