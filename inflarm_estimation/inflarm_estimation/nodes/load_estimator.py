"""Estimates the tip load and the link deflections from motor angles and torques (Fig 5 of 000_).

Every joint_states sample gives q_m and the torques the motors apply (``effort``, the
ros2_control convention); their negative is the paper's tau_m, the load torque on the motor
axes (eq. 6). A ``LoadTracker`` (``inflarm_estimation.elastostatic``) follows the branch of
solutions the stream is on, from sample to sample, and returns the tip force, the spring
deflections and the deflected tip; it starts cold (a search over every admissible load) on the
first sample and when the input jumps. Where a second admissible load fits the torques the
sample is reported 'ambiguous' (in diagnostics, with the loads) and nothing is published for
it. Each link's bending moment is checked against the wrinkling moment at its pressure (eq. 3).

Subscribes:
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS with a depth of 100, which absorbs
        bursts at 1 kHz): joint_1..joint_3 with position (within the joint limits) and
        effort; other joints are ignored.
Publishes (only for samples whose estimate converged, stamped with the sample's stamp):
    estimated_joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): all 7 URDF joints in
        the URDF's order, motors as measured and springs as estimated: positions [rad] and
        efforts [N m] (motors: the torque they apply; springs: their elastic torque k q_k,
        eq. 7). robot_state_publisher fed with it draws the deflected arm.
    estimated_wrench (geometry_msgs/WrenchStamped, RELIABLE_QOS): the tip force [N] in the
        ``tip`` frame (the deflected end of link 2 in the URDF), where its moment is zero.
    estimated_tip (geometry_msgs/PointStamped, RELIABLE_QOS): deflected tip [m], base frame.
    link_status (std_msgs/String: LinkStatus JSON, RELIABLE_QOS): one message per link for
        the latest estimate, at ``link_status_rate_hz`` (a link's margin changes slowly; a
        JSON message per link and sample at 1 kHz would cost more than the estimate).
Publishes always:
    diagnostics (diagnostic_msgs/DiagnosticArray, about 1 Hz): samples, estimates and
        rejections since the last report (``samples_total`` against the publisher's count
        gives the samples lost before the node), statuses, cold starts, the scheduling it
        runs under (``SCHED_FIFO 50`` by default, `spin_node`), the latest status,
        alternatives and conditioning. A report with no sample since the
        last one, the last sample older than ``stall_timeout_s`` (steady clock), says the
        stream stalled (level STALE) and for how long; before the first sample, WARN.
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    max_condition_number (double): J_m conditioning beyond which no estimate is trusted.
    max_force_n (double): largest admissible load [N]; a solution above it is no load.
    jump.motor_step_rad, jump.torque_step_nm (double): a change between samples larger than
        these restarts the tracker cold.
    stall_timeout_s (double, read-only): joint_states silent this long is a stalled stream.
    link_status_rate_hz (double, read-only): rate of link_status.
    frame_id (string, read-only): base frame of the outputs.
    tip_frame_id (string, read-only): frame of the estimated wrench.
"""

from collections import Counter
import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped, WrenchStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from inflarm_estimation.elastostatic import DEFAULT_MAX_FORCE, LoadTracker
from inflarm_model.elastostatics import link_moments
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import wrinkling_moment
from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    arm_from_parameters,
    check_arm_parameters,
)
from inflarm_model.ros_conversions import joint_arrays
from inflarm_model.urdf import TIP_LINK
from inflarm_msgs_json import LinkStatus
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.diagnostics import (
    ERROR,
    OK,
    STALE,
    WARN,
    DiagnosticsPublisher,
    diagnostic_status,
)
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS
from inflarm_msgs_json.ros.spin import scheduling, spin_node

PARAMETERS = ARM_PARAMETERS + (
    Parameter('max_condition_number', 1e6,
              'condition number of J_m beyond which the configuration counts as singular',
              range=(10.0, 1e12)),
    Parameter('max_force_n', DEFAULT_MAX_FORCE,
              'largest admissible tip load [N]: a solution above it is not a load',
              range=(1.0, 10000.0)),
    Parameter('jump.motor_step_rad', 0.05,
              'a motor angle change between samples above this restarts the tracker [rad]',
              range=(1e-4, 1.0)),
    Parameter('jump.torque_step_nm', 5.0,
              'a motor torque change between samples above this restarts the tracker [N m]',
              range=(1e-3, 100.0)),
    Parameter('stall_timeout_s', 0.5,
              'joint_states silent for longer than this is reported as a stalled stream [s]',
              range=(0.01, 60.0), read_only=True),
    Parameter('link_status_rate_hz', 10.0, 'rate of link_status [Hz]', range=(0.1, 1000.0),
              read_only=True),
    Parameter('frame_id', 'base_link', 'base frame of the outputs', read_only=True),
    Parameter('tip_frame_id', TIP_LINK, 'frame of the estimated wrench (URDF tip link)',
              read_only=True),
)
# JOINT_STATE_QOS, deeper: a Python callback at 1 kHz must not lose samples to a short stall.
JOINT_STATE_INPUT_QOS = QoSProfile(depth=100, reliability=JOINT_STATE_QOS.reliability,
                                   history=JOINT_STATE_QOS.history)
# SCHED_FIFO priority of the node's process (`spin_node`), ros2_control's for its control
# loop: at 1 kHz a busy machine must not keep the node from its samples
REALTIME_PRIORITY = 50
LINKS = ('link_1', 'link_2')
MOTORS = FlexibleArm.MOTOR_JOINT_NAMES


class LoadEstimator(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('load_estimator', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, check=check_arm_parameters,
                                         on_set=self.on_parameters_set)
        problem = check_arm_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.arm = arm_from_parameters(self.params)
        self.tracker = self.make_tracker()
        self.statuses: Counter[str] = Counter()  # estimate statuses since the last diagnostics
        self.samples_total = 0
        self.last_estimate = None
        self.last_sample_at: float | None = None  # time.monotonic() of the last message [s]
        self.last_pose: tuple[object, np.ndarray, np.ndarray] | None = None  # stamp, q, force
        self.create_guarded_subscription(
            JointState, 'joint_states', self.on_joint_states, JOINT_STATE_INPUT_QOS)
        # One message of each output, refilled per sample: at 1 kHz building new ones would
        # cost more than the estimate (rclpy copies a message when it publishes it).
        self.pose_msg = JointState(name=list(FlexibleArm.JOINT_NAMES))
        self.wrench_msg = WrenchStamped()
        self.wrench_msg.header.frame_id = self.params['tip_frame_id']
        self.tip_msg = PointStamped()
        self.tip_msg.header.frame_id = self.params['frame_id']
        self.pose_pub = self.create_publisher(JointState, 'estimated_joint_states',
                                              JOINT_STATE_QOS)
        self.wrench_pub = self.create_publisher(WrenchStamped, 'estimated_wrench', RELIABLE_QOS)
        self.tip_pub = self.create_publisher(PointStamped, 'estimated_tip', RELIABLE_QOS)
        self.link_status_pub = self.create_publisher(String, 'link_status', RELIABLE_QOS)
        self.diagnostics = DiagnosticsPublisher(self, self.diagnostic_status)
        self.create_guarded_timer(1.0 / self.params['link_status_rate_hz'],
                                  self.publish_link_status)
        self.get_logger().info('ready: estimating the tip load from joint_states')

    def make_tracker(self) -> LoadTracker:
        p = self.params
        return LoadTracker(self.arm, p['arm.spring_stiffness'],
                           max_motor_step=p['jump.motor_step_rad'],
                           max_torque_step=p['jump.torque_step_nm'],
                           max_condition=p['max_condition_number'], max_force=p['max_force_n'])

    def on_parameters_set(self, changed: dict) -> None:
        self.tracker = self.make_tracker()  # a new model: the history no longer applies

    def on_joint_states(self, msg: JointState) -> None:
        self.last_sample_at = time.monotonic()  # the stream is alive, even if this one is bad
        sample = joint_arrays(msg, MOTORS, ('position', 'effort'))
        q_m, effort = sample['position'], sample['effort']
        estimate = self.tracker.update(q_m, -effort)  # effort: the torque the motors apply
        self.samples_total += 1
        self.statuses[estimate.status] += 1
        self.last_estimate = estimate
        if not estimate.converged:
            self.problems.warn('estimate', f'no estimate for this sample: {estimate.reason}',
                               kind=estimate.status)
            return
        self.publish_estimate(msg.header.stamp, q_m, effort, estimate)

    def publish_estimate(self, stamp, q_m: np.ndarray, effort: np.ndarray, estimate) -> None:
        q = FlexibleArm.assemble_q(q_m, estimate.q_k)
        pose, wrench, tip = self.pose_msg, self.wrench_msg, self.tip_msg
        pose.header.stamp = wrench.header.stamp = tip.header.stamp = stamp
        pose.position = q.tolist()
        pose.effort = FlexibleArm.assemble_q(effort, estimate.tau_k).tolist()
        self.pose_pub.publish(pose)
        tip_rotation = self.arm.fk(q)[:3, :3]  # tip frame -> base frame
        force = wrench.wrench.force
        force.x, force.y, force.z = (tip_rotation.T @ estimate.force).tolist()
        self.wrench_pub.publish(wrench)
        tip.point.x, tip.point.y, tip.point.z = estimate.tip_position.tolist()
        self.tip_pub.publish(tip)
        self.last_pose = (stamp, q, estimate.force)

    def publish_link_status(self) -> None:
        """Each link's bending moment against its wrinkling moment, for the latest estimate."""
        if self.last_pose is None:
            return
        _, q, force = self.last_pose
        self.last_pose = None  # once per estimate
        moments = link_moments(self.arm, q, force)
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
        silent = (math.inf if self.last_sample_at is None
                  else time.monotonic() - self.last_sample_at)
        if self.last_sample_at is None:
            level, message = WARN, 'no joint_states samples'
        elif samples == 0 and silent > self.params['stall_timeout_s']:
            level, message = STALE, (f'joint_states stalled: no sample for {silent:.1f} s '
                                     f"(stall_timeout_s {self.params['stall_timeout_s']:g})")
        elif samples == 0:
            level, message = WARN, 'joint_states arrive, but none could be estimated since ' \
                'the last report (see rejected_samples_total)'
        elif converged == samples:
            level, message = OK, 'converged'
        else:
            level = ERROR if converged == 0 else WARN
            message = f'{samples - converged} of {samples} samples without an estimate'
        status = diagnostic_status(
            'load_estimator: elastostatic estimate', 'inflatable_arm', level, message,
            samples=samples, converged=converged, samples_total=self.samples_total,
            rejected_samples_total=rejected,
            cold_starts_total=self.tracker.cold_starts, scheduling=scheduling(),
            # in 0.1 s steps: what a stall needs, and the same in every replay of a recording
            seconds_since_sample=round(silent, 1),
            statuses=dict(self.statuses) or 'none',
            last_status='none' if estimate is None else estimate.status,
            last_alternatives='none' if estimate is None else '; '.join(
                str(f.round(2).tolist()) for f in estimate.alternatives) or 'none',
            last_iterations=0 if estimate is None else estimate.iterations,
            last_condition_number=math.nan if estimate is None else estimate.condition_number)
        self.statuses.clear()
        return [status]


def main(args: list[str] | None = None) -> None:
    # fed at 1 kHz: the cheaper executor (the estimation README has it measured)
    spin_node(LoadEstimator, args, default_executor='events',
              default_realtime_priority=REALTIME_PRIORITY)


if __name__ == '__main__':
    main()
