"""Publishes the URDF of the inflatable-link arm for RViz and other description users.

Publishes:
    robot_description (std_msgs/String, LATCHED_QOS): URDF of the 7-DOF pseudo-rigid arm
        (Table 2), spring joints as revolute joints with their stiffness recorded in
        ``<inflarm:spring>`` elements; republished when the stiffness changes.
Parameters:
    arm.* (see inflarm_model.nodes.arm_parameters): link length, spring offset, link radius,
        spring stiffness, link pressure.
"""

from rclpy.node import Node
from std_msgs.msg import String

from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    check_arm_parameters,
    urdf_from_parameters,
)
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import declare_parameters
from inflarm_msgs_json.ros.qos import LATCHED_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node


class RobotDescription(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('robot_description', **kwargs)
        self.params = declare_parameters(self, ARM_PARAMETERS, check=check_arm_parameters,
                                         on_set=self.on_parameters_set)
        problem = check_arm_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.description_pub = self.create_publisher(
            String, 'robot_description', LATCHED_QOS,
            event_callbacks=publisher_events(self, 'robot_description'))
        self.publish()
        self.get_logger().info('ready: robot_description published')

    def on_parameters_set(self, changed: dict) -> None:
        if 'arm.spring_stiffness' in changed:
            self.publish()
            self.get_logger().info('stiffness changed: robot_description republished')

    def publish(self) -> None:
        self.description_pub.publish(String(data=urdf_from_parameters(self.params)))


def main(args: list[str] | None = None) -> None:
    spin_node(RobotDescription, args)


if __name__ == '__main__':
    main()
