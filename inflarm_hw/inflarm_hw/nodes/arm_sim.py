"""Simulated inflatable-link arm: motors follow position commands, links deflect under a tip load.

Subscribes:
    motor_position_command (sensor_msgs/JointState, COMMAND_QOS): target angles [rad] of some
        or all of joint_1..joint_3, by name, within the joint limits (a command with a joint
        outside its limits is rejected whole), and optionally velocities [rad/s], a
        feed-forward added to each motor's position loop; the positions are those due at the
        command's stamp, carried on by the velocities to the simulation's time.
Publishes:
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): joint_1..joint_3 angles [rad],
        velocities [rad/s] and, in ``effort``, the torque each motor applies [N·m]: the
        ros2_control convention, which in statics is -tau_m, the negative of the load torque
        on the motor axis (eq. 6 of 000_...); with sensor noise.
    tip_position_truth (geometry_msgs/PointStamped, SENSOR_QOS): true deflected tip [m].
    spring_states_truth (sensor_msgs/JointState, SENSOR_QOS): true spring_1..spring_4
        deflections [rad] and torques [N·m].
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    tip_force_n (double[3]): external tip load [N], base frame; may change at runtime.
    rate_hz (double, read-only): publishing rate; each step simulates the time that passed
        since the previous one (at most 0.5 s), so a late step does not slow the arm down.
    initial_motor_positions_rad (double[3], read-only).
    motor.time_constant_s, motor.max_velocity_rad_s (double, read-only): motor response.
    noise.position_rad, noise.effort_nm (double): sensor noise.
    wrinkling (bool, read-only): saturate link moments at M_max (Table 3).
    cmd_timeout_s (double, 0.05-5): without a command for this long the motors hold where
        they are (the fail-safe of a silent controller); 0 commands yet: they hold the start.
    seed (int, read-only): noise seed, -1 for a random one.
    frame_id (string, read-only): base frame.
"""

import time

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import JointState

from inflarm_hw.nodes.plant_parameters import (
    ARM_PLANT_PARAMETERS,
    apply_arm_plant_parameter,
    arm_plant_from_parameters,
    check_arm_plant_parameters,
)
from inflarm_hw.realtime import ElapsedSteps
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.ros_conversions import joint_arrays, joint_state
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import COMMAND_QOS, JOINT_STATE_QOS, SENSOR_QOS
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = ARM_PLANT_PARAMETERS + (
    Parameter('rate_hz', 50.0, 'simulation and publishing rate [Hz]', range=(1.0, 1000.0),
              read_only=True),
    Parameter('cmd_timeout_s', 1.0,
              'hold the motors where they are after this long without a command [s]',
              range=(0.05, 5.0)),
    Parameter('seed', -1, 'noise seed, -1 for a random one', range=(-1, 2**31 - 1),
              read_only=True),
    Parameter('frame_id', 'base_link', 'base frame', read_only=True),
)
MOTORS = FlexibleArm.MOTOR_JOINT_NAMES
MAX_COMMAND_AGE_S = 0.5  # a set point is carried to the last step's time by at most this


class ArmSim(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('arm_sim', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS,
                                             check=check_arm_plant_parameters,
                                             on_set=self.on_parameters_set)
        problem = check_arm_plant_parameters(p)
        if problem is not None:
            raise ValueError(problem)
        seed = p['seed']
        self.sim = arm_plant_from_parameters(p, np.random.default_rng(None if seed < 0 else seed))
        self.dt = 1.0 / p['rate_hz']
        # Step by the time that passed, not the timer's period: a late callback (a stalled
        # host) must not leave the arm behind the IK's time-stamped set points.
        self.elapsed = ElapsedSteps(max_step_s=MAX_COMMAND_AGE_S)
        self.last_command_time: float | None = None  # steady clock; None: holding
        self.last_step_ns = self.get_clock().now().nanoseconds  # node clock of the last step

        self.create_guarded_subscription(
            JointState, 'motor_position_command', self.on_command, COMMAND_QOS)
        self.joint_state_pub = self.create_publisher(JointState, 'joint_states', JOINT_STATE_QOS)
        self.tip_pub = self.create_publisher(PointStamped, 'tip_position_truth', SENSOR_QOS)
        self.spring_pub = self.create_publisher(JointState, 'spring_states_truth', SENSOR_QOS)
        self.create_guarded_timer(self.dt, self.step)
        self.get_logger().info(f"ready: tip load {p['tip_force_n']} N at {p['rate_hz']} Hz")

    def on_parameters_set(self, changed: dict) -> None:
        for name, value in changed.items():
            change = apply_arm_plant_parameter(self.sim, name, value)
            if change is not None:
                self.get_logger().info(change)

    def on_command(self, msg: JointState) -> None:
        names = [n for n in MOTORS if n in msg.name]
        unknown = sorted(set(msg.name) - set(MOTORS))
        if unknown or not names:
            raise InputError('unknown joint', f'unknown joints {unknown or list(msg.name)}, '
                                              f'expected some of {list(MOTORS)}')
        arrays = joint_arrays(msg, names, optional=('velocity',))
        target, feed_forward = self.sim.target.copy(), np.zeros(3)  # unnamed joints: no ff
        for k, name in enumerate(names):
            target[MOTORS.index(name)] = arrays['position'][k]
            if arrays['velocity'] is not None:
                feed_forward[MOTORS.index(name)] = arrays['velocity'][k]
        # The set point is due at its stamp; the next step carries it on from the last one's
        # time, so start it where it stood then (a stamp of 0: due now). A stamp after the last
        # step (this simulator late, the controller not) is carried back.
        stamp_ns = Time.from_msg(msg.header.stamp).nanoseconds or self.last_step_ns
        age = float(np.clip((self.last_step_ns - stamp_ns) * 1e-9, -MAX_COMMAND_AGE_S,
                            MAX_COMMAND_AGE_S))
        self.sim.command(target + feed_forward * age, feed_forward)
        self.last_command_time = time.monotonic()

    def step(self) -> None:
        timeout = self.params['cmd_timeout_s']
        if (self.last_command_time is not None
                and time.monotonic() - self.last_command_time > timeout):
            self.last_command_time = None
            self.sim.command(self.sim.q_m)
            self.get_logger().warning(
                f'no motor_position_command for {timeout} s: holding the motors where they are')
        dt = self.elapsed()
        if dt <= 0.0:
            return
        try:
            state = self.sim.step(dt)
        except RuntimeError as err:  # no equilibrium: hold the last state, say why
            self.problems.warn('step', str(err))
            return
        now = self.get_clock().now()
        self.last_step_ns = now.nanoseconds
        stamp = now.to_msg()
        self.joint_state_pub.publish(joint_state(
            FlexibleArm.MOTOR_JOINT_NAMES, stamp, position=state.q_m, velocity=state.dq_m,
            effort=-state.tau_m))
        self.spring_pub.publish(joint_state(
            FlexibleArm.SPRING_JOINT_NAMES, stamp, position=state.q_k,
            effort=self.sim.stiffness * state.q_k))
        tip = PointStamped()
        tip.header.stamp = stamp
        tip.header.frame_id = self.params['frame_id']
        tip.point.x, tip.point.y, tip.point.z = state.tip_position.tolist()
        self.tip_pub.publish(tip)


def main(args: list[str] | None = None) -> None:
    spin_node(ArmSim, args)


if __name__ == '__main__':
    main()
