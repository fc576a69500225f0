"""Publishes sinusoidal joint states: the smallest live data source, for smoke tests and demos.

Publishes:
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): positions [rad] and velocities [rad/s]
        of ``joint_names``, each a sine of amplitude ``amplitude_rad`` and a phase per joint.
Parameters:
    joint_names (string[], read-only): joint names.
    rate_hz (double, 0.1-1000): publishing rate; may change at runtime.
    amplitude_rad (double, 0-pi): sine amplitude.
    frequency_hz (double, 0-10): sine frequency.
"""

import math
import time

from rclpy.node import Node
from sensor_msgs.msg import JointState

from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = (
    Parameter('joint_names', ['joint_1', 'joint_2', 'joint_3'], 'joint names', read_only=True),
    Parameter('rate_hz', 50.0, 'publishing rate [Hz]', range=(0.1, 1000.0)),
    Parameter('amplitude_rad', 0.5, 'sine amplitude [rad]', range=(0.0, math.pi)),
    Parameter('frequency_hz', 0.2, 'sine frequency [Hz]', range=(0.0, 10.0)),
)


class DemoJointPublisher(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('demo_joint_publisher', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, on_set=self.on_parameters_set)
        self.joint_state_pub = self.create_publisher(
            JointState, 'joint_states', JOINT_STATE_QOS,
            event_callbacks=publisher_events(self, 'joint_states'))
        self.start_time = time.monotonic()
        self.timer = self.create_guarded_timer(1.0 / self.params['rate_hz'], self.publish)
        self.get_logger().info(
            f"ready: {len(self.params['joint_names'])} joints at {self.params['rate_hz']} Hz")

    def on_parameters_set(self, changed: dict) -> None:
        if 'rate_hz' in changed:
            self.timer.timer_period_ns = int(1e9 / changed['rate_hz'])
            self.get_logger().info(f"rate changed to {changed['rate_hz']} Hz")

    def publish(self) -> None:
        t = time.monotonic() - self.start_time
        omega = 2.0 * math.pi * self.params['frequency_hz']
        amplitude = self.params['amplitude_rad']
        names = self.params['joint_names']
        phases = [2.0 * math.pi * i / len(names) for i in range(len(names))]
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = list(names)
        msg.position = [amplitude * math.sin(omega * t + phase) for phase in phases]
        msg.velocity = [amplitude * omega * math.cos(omega * t + phase) for phase in phases]
        self.joint_state_pub.publish(msg)


def main(args: list[str] | None = None) -> None:
    spin_node(DemoJointPublisher, args)


if __name__ == '__main__':
    main()
