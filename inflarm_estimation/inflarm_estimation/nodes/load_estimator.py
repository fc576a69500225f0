"""Estimates the tip load and the link deflections from motor angles and torques (Fig 5 of 000_).

Every joint_states sample gives q_m and the torques the motors apply (``effort``, the
ros2_control convention); their negative is the paper's tau_m, the load torque on the motor
axes (eq. 6). The elastostatic estimate (``inflarm_estimation.elastostatic``) returns the tip
force, the spring deflections and the deflected tip. Each link's bending moment is checked
against the wrinkling moment at its pressure (eq. 3).

Subscribes:
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): joint_1..joint_3 with position
        (within the joint limits) and effort; other joints are ignored.
Publishes (only for samples whose estimate converged, stamped with the sample's stamp):
    estimated_joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): all 7 URDF joints,
        motors as measured and springs as estimated: robot_state_publisher fed with it draws
        the deflected arm.
    estimated_wrench (geometry_msgs/WrenchStamped, RELIABLE_QOS): the tip force [N] in the
        ``tip`` frame (the deflected end of link 2 in the URDF), where its moment is zero.
    spring_deflections (sensor_msgs/JointState, RELIABLE_QOS): spring_1..spring_4 deflections
        [rad] and torques [N·m].
    estimated_tip (geometry_msgs/PointStamped, RELIABLE_QOS): deflected tip [m], base frame.
    link_status (std_msgs/String: LinkStatus JSON, RELIABLE_QOS): one message per link.
Publishes always:
    diagnostics (diagnostic_msgs/DiagnosticArray, about 1 Hz): samples, estimates and
        rejections since the last report, the latest status and conditioning.
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    max_condition_number (double): J_m conditioning beyond which no estimate is trusted.
    frame_id (string, read-only): base frame of the outputs.
    tip_frame_id (string, read-only): frame of the estimated wrench.
"""

from collections import Counter
import math

from diagnostic_msgs.msg import DiagnosticStatus
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
from inflarm_model.ros_conversions import joint_arrays, joint_state
from inflarm_model.urdf import TIP_LINK
from inflarm_msgs_json import LinkStatus
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.diagnostics import (
    ERROR,
    OK,
    WARN,
    DiagnosticsPublisher,
    diagnostic_status,
)
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = ARM_PARAMETERS + (
    Parameter('max_condition_number', 1e6,
              'condition number of J_m beyond which the configuration counts as singular',
              range=(10.0, 1e12)),
    Parameter('frame_id', 'base_link', 'base frame of the outputs', read_only=True),
    Parameter('tip_frame_id', TIP_LINK, 'frame of the estimated wrench (URDF tip link)',
              read_only=True),
)
LINKS = ('link_1', 'link_2')
MOTORS = FlexibleArm.MOTOR_JOINT_NAMES


class LoadEstimator(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('load_estimator', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        problem = check_arm_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.arm = arm_from_parameters(self.params)
        self.statuses: Counter[str] = Counter()  # estimate statuses since the last diagnostics
        self.last_estimate = None
        self.create_guarded_subscription(
            JointState, 'joint_states', self.on_joint_states, JOINT_STATE_QOS)
        self.pose_pub = self.create_publisher(JointState, 'estimated_joint_states',
                                              JOINT_STATE_QOS)
        self.wrench_pub = self.create_publisher(WrenchStamped, 'estimated_wrench', RELIABLE_QOS)
        self.springs_pub = self.create_publisher(JointState, 'spring_deflections', RELIABLE_QOS)
        self.tip_pub = self.create_publisher(PointStamped, 'estimated_tip', RELIABLE_QOS)
        self.link_status_pub = self.create_publisher(String, 'link_status', RELIABLE_QOS)
        self.diagnostics = DiagnosticsPublisher(self, self.diagnostic_status)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(
            lambda parameters: self.params.update({q.name: q.value for q in parameters}))
        self.get_logger().info('ready: estimating the tip load from joint_states')

    def on_set_parameters(self, parameters) -> SetParametersResult:
        problem = check_arm_parameters({q.name: q.value for q in parameters})
        return SetParametersResult(successful=problem is None, reason=problem or '')

    def on_joint_states(self, msg: JointState) -> None:
        sample = joint_arrays(msg, MOTORS, ('position', 'effort'))
        q_m, tau_m = sample['position'], -sample['effort']  # effort: the motors' own torque
        estimate = estimate_load_and_pose(
            self.arm, q_m, tau_m, self.params['arm.spring_stiffness'],
            max_condition=self.params['max_condition_number'])
        self.statuses[estimate.status] += 1
        self.last_estimate = estimate
        if not estimate.converged:
            self.problems.warn('estimate', f'no estimate for this sample: {estimate.reason}',
                               kind=estimate.status)
            return
        self.publish_estimate(msg.header.stamp, q_m, estimate)

    def publish_estimate(self, stamp, q_m: np.ndarray, estimate) -> None:
        q = FlexibleArm.assemble_q(q_m, estimate.q_k)
        self.pose_pub.publish(joint_state(FlexibleArm.JOINT_NAMES, stamp, position=q))
        wrench = WrenchStamped()
        wrench.header.stamp = stamp
        wrench.header.frame_id = self.params['tip_frame_id']
        tip_rotation = self.arm.fk(q)[:3, :3]  # tip frame -> base frame
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = (
            tip_rotation.T @ estimate.force).tolist()
        self.wrench_pub.publish(wrench)
        springs = joint_state(FlexibleArm.SPRING_JOINT_NAMES, stamp, position=estimate.q_k,
                              effort=estimate.tau_k)
        springs.header.frame_id = self.params['frame_id']
        self.springs_pub.publish(springs)
        tip = PointStamped()
        tip.header.stamp = stamp
        tip.header.frame_id = self.params['frame_id']
        tip.point.x, tip.point.y, tip.point.z = estimate.tip_position.tolist()
        self.tip_pub.publish(tip)

        moments = link_moments(self.arm, q, estimate.force)
        radius = self.params['arm.link_radius_m']
        for link, pressure, moment in zip(LINKS, self.params['arm.link_pressure_pa'],
                                          moments.tolist(), strict=True):
            status = LinkStatus.from_moments(link, pressure, wrinkling_moment(pressure, radius),
                                             moment)
            self.link_status_pub.publish(to_string_msg(status))
            if status.margin < 0.0:
                self.problems.warn(
                    link, f'moment {moment:.2f} N m over the wrinkling moment '
                    f'{status.wrinkling_moment:.2f} N m at {pressure / 1000:.0f} kPa',
                    kind='wrinkling')

    def diagnostic_status(self) -> list[DiagnosticStatus]:
        rejected = self.problems.counts.get('joint_states', 0)
        samples = sum(self.statuses.values())
        converged = self.statuses['converged']
        estimate = self.last_estimate
        if samples == 0:
            level, message = WARN, 'no joint_states samples'
        elif converged == samples:
            level, message = OK, 'converged'
        else:
            level = ERROR if converged == 0 else WARN
            message = f'{samples - converged} of {samples} samples without an estimate'
        status = diagnostic_status(
            'load_estimator: elastostatic estimate', 'inflatable_arm', level, message,
            samples=samples, converged=converged, rejected_samples_total=rejected,
            statuses=dict(self.statuses) or 'none',
            last_iterations=0 if estimate is None else estimate.iterations,
            last_condition_number=math.nan if estimate is None else estimate.condition_number)
        self.statuses.clear()
        return [status]


def main(args: list[str] | None = None) -> None:
    spin_node(LoadEstimator, args)


if __name__ == '__main__':
    main()
