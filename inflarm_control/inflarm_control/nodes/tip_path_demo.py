"""Drives the inflatable arm's tip back and forth along a straight path, as in Fig 10 of 000_...,
and logs how far the true tip strays from it: the demo and end-to-end check of the estimation
and elastostatic IK chain.

Publishes:
    tip_trajectory (nav_msgs/Path, RELIABLE_QOS): ``samples`` poses from one end to the other
        over ``duration_s``, each stamped with the time it is due; every ``duration_s +
        pause_s`` the other way round.
Subscribes:
    tip_position_truth (geometry_msgs/PointStamped, SENSOR_QOS): the simulated true tip.
Parameters:
    start, goal (double[3], read-only): path ends [m], base frame.
    duration_s, pause_s (double, read-only): traverse and rest times [s].
    lead_s (double, read-only): each path is due this long after it is sent, so that the IK has
        computed it by then and the tip follows the stamps (error measured against them).
    samples (int, read-only): poses per path.
    frame_id (string, read-only).
"""


from geometry_msgs.msg import PointStamped, PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.time import Time

from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = (
    Parameter('start', [0.9, -0.2, 0.1], 'one end of the path [m]', read_only=True),
    Parameter('goal', [0.7, 0.3, -0.1], 'other end of the path [m]', read_only=True),
    Parameter('duration_s', 5.0, 'time to traverse the path [s]', range=(0.1, 600.0),
              read_only=True),
    Parameter('pause_s', 3.0, 'rest at each end [s]', range=(0.0, 600.0), read_only=True),
    Parameter('lead_s', 0.5, 'a path is due this long after it is sent [s]', range=(0.0, 10.0),
              read_only=True),
    Parameter('samples', 50, 'poses per path', range=(2, 100000), read_only=True),
    Parameter('frame_id', 'base_link', 'frame of the path', read_only=True),
)


class TipPathDemo(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('tip_path_demo', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS)
        self.ends = (np.array(p['start']), np.array(p['goal']))
        if any(end.shape != (3,) or not np.isfinite(end).all() for end in self.ends):
            raise ValueError(f'start and goal must be 3 finite numbers, got {self.ends}')
        self.traverse = 0
        self.path_start: int | None = None  # node clock time the current path is due [ns]
        self.path_ends = self.ends
        self.tip: np.ndarray | None = None
        self.errors: list[float] = []
        self.path_pub = self.create_publisher(Path, 'tip_trajectory', RELIABLE_QOS)
        self.create_guarded_subscription(PointStamped, 'tip_position_truth', self.on_truth,
                                         SENSOR_QOS)
        self.create_guarded_timer(p['duration_s'] + p['pause_s'], self.next_traverse)
        self.get_logger().info(f"ready: tip path {p['start']} <-> {p['goal']} m")

    def reference(self, elapsed: float) -> np.ndarray:
        """Where the tip should be ``elapsed`` seconds into the current traverse."""
        a, b = self.path_ends
        s = min(max(elapsed / self.params['duration_s'], 0.0), 1.0)
        return a + s * (b - a)

    def next_traverse(self) -> None:
        if self.path_start is not None:
            self.report()
            self.traverse += 1
        if self.path_pub.get_subscription_count() == 0:
            self.path_start = None
            return
        p = self.params
        # The first path starts where the tip is; then back and forth between the ends.
        if self.traverse == 0 and self.tip is not None:
            self.path_ends = (self.tip, self.ends[1])
        else:
            self.path_ends = self.ends if self.traverse % 2 == 0 else self.ends[::-1]
        now = self.get_clock().now() + Duration(seconds=p['lead_s'])
        path = Path()
        path.header.stamp = now.to_msg()
        path.header.frame_id = p['frame_id']
        for t in np.linspace(0.0, p['duration_s'], p['samples']):
            pose = PoseStamped()
            pose.header.frame_id = p['frame_id']
            pose.header.stamp = (now + Duration(seconds=float(t))).to_msg()
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
                self.reference(float(t)).tolist())
            pose.pose.orientation.w = 1.0
            path.poses.append(pose)
        self.path_pub.publish(path)
        self.path_start = now.nanoseconds  # node clock, as the truth's stamps
        self.errors = []

    def on_truth(self, msg: PointStamped) -> None:
        tip = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.isfinite(tip).all():
            raise InputError('not finite', f'tip {tip.tolist()} m')
        self.tip = tip
        if self.path_start is None:
            return
        elapsed = (Time.from_msg(msg.header.stamp).nanoseconds - self.path_start) * 1e-9
        self.errors.append(float(np.linalg.norm(tip - self.reference(elapsed))))

    def report(self) -> None:
        if not self.errors:
            self.get_logger().warning(f'traverse {self.traverse}: no tip_position_truth received')
            return
        self.get_logger().info(
            f'traverse {self.traverse}: true tip off the path by at most '
            f'{max(self.errors) * 1000:.1f} mm, {self.errors[-1] * 1000:.2f} mm at the end')


def main(args: list[str] | None = None) -> None:
    spin_node(TipPathDemo, args)


if __name__ == '__main__':
    main()
