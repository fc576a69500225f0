"""Estimates the tip load and the link deflections from motor angles and torques (Fig 5 of 000_).

Every joint_states sample gives q_m and tau_m (``effort``, the load torques on the motor axes,
eq. 6); the elastostatic estimate (``inflarm_estimation.elastostatic``) returns the tip force,
the spring deflections and the deflected tip. Each link's bending moment is checked against the
wrinkling moment at its pressure (eq. 3).

Subscribes:
    joint_states (sensor_msgs/JointState, SENSOR_QOS): joint_1..joint_3 with position and
        effort (other joints are ignored).
Publishes (only for samples whose estimate converged):
    estimated_wrench (geometry_msgs/WrenchStamped, RELIABLE_QOS): tip force [N], moments zero.
    spring_deflections (sensor_msgs/JointState, RELIABLE_QOS): spring_1..spring_4 deflections
        [rad] and torques [N·m].
    estimated_tip (geometry_msgs/PointStamped, RELIABLE_QOS): deflected tip [m].
    link_status (std_msgs/String: LinkStatus JSON, RELIABLE_QOS): one message per link.
Publishes always:
    diagnostics (diagnostic_msgs/DiagnosticArray): estimate status, iterations, conditioning.
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    max_condition_number (double): J_m conditioning beyond which no estimate is trusted.
    frame_id (string, read-only): base frame of the outputs.
"""

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, WrenchStamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from inflarm_estimation.elastostatic import estimate_load_and_pose
from inflarm_model.elastostatics import link_moments
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import wrinkling_moment
from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    arm_from_parameters,
    check_arm_parameters,
)
from inflarm_msgs_json import LinkStatus
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS, subscription_events
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = ARM_PARAMETERS + (
    Parameter('max_condition_number', 1e6,
              'condition number of J_m beyond which the configuration counts as singular',
              range=(10.0, 1e12)),
    Parameter('frame_id', 'base_link', 'base frame of the outputs', read_only=True),
)
LINKS = ('link_1', 'link_2')


class LoadEstimator(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('load_estimator', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        problem = check_arm_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.arm = arm_from_parameters(self.params)
        self.create_subscription(
            JointState, 'joint_states', self.on_joint_states, SENSOR_QOS,
            event_callbacks=subscription_events(self, 'joint_states'))
        self.wrench_pub = self.create_publisher(WrenchStamped, 'estimated_wrench', RELIABLE_QOS)
        self.springs_pub = self.create_publisher(JointState, 'spring_deflections', RELIABLE_QOS)
        self.tip_pub = self.create_publisher(PointStamped, 'estimated_tip', RELIABLE_QOS)
        self.link_status_pub = self.create_publisher(String, 'link_status', RELIABLE_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, 'diagnostics', RELIABLE_QOS)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(
            lambda parameters: self.params.update({q.name: q.value for q in parameters}))
        self.get_logger().info('ready: estimating the tip load from joint_states')

    def on_set_parameters(self, parameters) -> SetParametersResult:
        problem = check_arm_parameters({q.name: q.value for q in parameters})
        return SetParametersResult(successful=problem is None, reason=problem or '')

    def motor_sample(self, msg: JointState) -> tuple[np.ndarray, np.ndarray] | None:
        """(q_m, tau_m) from a joint state, or None (warned) when it lacks them."""
        names = FlexibleArm.MOTOR_JOINT_NAMES
        index = {name: i for i, name in enumerate(msg.name)}
        problem = None
        if any(name not in index for name in names):
            problem = f'expected joints {list(names)}, got {list(msg.name)}'
        elif len(msg.position) != len(msg.name) or len(msg.effort) != len(msg.name):
            problem = (f'expected a position and an effort per joint, got {len(msg.name)} names,'
                       f' {len(msg.position)} positions, {len(msg.effort)} efforts')
        else:
            q_m = np.array([msg.position[index[name]] for name in names])
            tau_m = np.array([msg.effort[index[name]] for name in names])
            if np.isfinite(q_m).all() and np.isfinite(tau_m).all():
                return q_m, tau_m
            problem = f'non-finite positions {q_m.tolist()} or efforts {tau_m.tolist()}'
        self.get_logger().warning(f'joint_states sample skipped: {problem}',
                                  throttle_duration_sec=2.0)
        return None

    def on_joint_states(self, msg: JointState) -> None:
        sample = self.motor_sample(msg)
        if sample is None:
            return
        q_m, tau_m = sample
        estimate = estimate_load_and_pose(
            self.arm, q_m, tau_m, self.params['arm.spring_stiffness'],
            max_condition=self.params['max_condition_number'])
        self.publish_diagnostics(estimate)
        if not estimate.converged:
            self.get_logger().warning(f'no estimate for this sample: {estimate.reason}',
                                      throttle_duration_sec=2.0)
            return
        header = msg.header
        header.frame_id = self.params['frame_id']

        wrench = WrenchStamped(header=header)
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = (
            estimate.force.tolist())
        self.wrench_pub.publish(wrench)
        springs = JointState(header=header, name=list(FlexibleArm.SPRING_JOINT_NAMES),
                             position=estimate.q_k.tolist(), effort=estimate.tau_k.tolist())
        self.springs_pub.publish(springs)
        tip = PointStamped(header=header)
        tip.point.x, tip.point.y, tip.point.z = estimate.tip_position.tolist()
        self.tip_pub.publish(tip)

        moments = link_moments(self.arm, FlexibleArm.assemble_q(q_m, estimate.q_k),
                               estimate.force)
        radius = self.params['arm.link_radius_m']
        for link, pressure, moment in zip(LINKS, self.params['arm.link_pressure_pa'],
                                          moments.tolist(), strict=True):
            status = LinkStatus.from_moments(link, pressure, wrinkling_moment(pressure, radius),
                                             moment)
            self.link_status_pub.publish(to_string_msg(status))
            if status.margin < 0.0:
                self.get_logger().warning(
                    f'{link}: moment {moment:.2f} N m over the wrinkling moment '
                    f'{status.wrinkling_moment:.2f} N m at {pressure / 1000:.0f} kPa',
                    throttle_duration_sec=2.0)

    def publish_diagnostics(self, estimate) -> None:
        status = DiagnosticStatus(
            name='load_estimator: elastostatic estimate', hardware_id='inflatable_arm',
            level=DiagnosticStatus.OK if estimate.converged else DiagnosticStatus.ERROR,
            message=estimate.status if estimate.converged else estimate.reason)
        condition = estimate.condition_number
        status.values = [
            KeyValue(key='iterations', value=str(estimate.iterations)),
            KeyValue(key='condition_number',
                     value=f'{condition:.4g}' if math.isfinite(condition) else 'inf'),
            KeyValue(key='status', value=estimate.status),
        ]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(array)


def main(args: list[str] | None = None) -> None:
    spin_node(LoadEstimator, args)


if __name__ == '__main__':
    main()
