"""Reports what flows on ``joint_states``: message rate and latest positions, at a fixed period.

Subscribes:
    joint_states (sensor_msgs/JointState, SENSOR_QOS: best effort, so that it hears reliable and
        best-effort publishers alike, as ``ros2 topic hz`` does)
Parameters:
    report_period_s (double, 0.1-60): how often to log a report.
"""

import math
import time

from rclpy.node import Node
from sensor_msgs.msg import JointState

from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = (
    Parameter('report_period_s', 1.0, 'report period [s]', range=(0.1, 60.0)),
)


class JointStateMonitor(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('joint_state_monitor', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        self.latest: JointState | None = None
        self.received = 0
        self.rejected = 0
        self.window_start = time.monotonic()
        self.create_guarded_subscription(JointState, 'joint_states', self.on_joint_state,
                                         SENSOR_QOS)
        self.create_guarded_timer(self.params['report_period_s'], self.report)
        self.get_logger().info('ready: listening on joint_states')

    def on_joint_state(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name) or not all(map(math.isfinite, msg.position)):
            self.rejected += 1
            raise InputError('bad positions', 'expected one finite position per name, got '
                                              f'{len(msg.name)} names and positions '
                                              f'{list(msg.position)}')
        self.latest = msg
        self.received += 1

    def report(self) -> None:
        now = time.monotonic()
        rate_hz = self.received / (now - self.window_start)
        self.window_start = now
        self.received = 0
        if self.latest is None:
            self.get_logger().info('no joint states yet')
            return
        positions = ', '.join(
            f'{name}={position:+.3f}'
            for name, position in zip(self.latest.name, self.latest.position, strict=True))
        self.get_logger().info(f'joint_states at {rate_hz:.1f} Hz: {positions}')


def main(args: list[str] | None = None) -> None:
    spin_node(JointStateMonitor, args)


if __name__ == '__main__':
    main()
