"""Simulated inflatable-link arm: motors follow position commands, links deflect under a tip load.

Subscribes:
    motor_position_command (sensor_msgs/JointState, COMMAND_QOS): target angles [rad] of some
        or all of joint_1..joint_3, by name.
Publishes:
    joint_states (sensor_msgs/JointState, SENSOR_QOS): joint_1..joint_3 angles [rad],
        velocities [rad/s] and, in ``effort``, the load torques on the motor axes [N·m]
        (tau_m = U_m^T f, eq. 6 of 000_...), with sensor noise.
    tip_position_truth (geometry_msgs/PointStamped, SENSOR_QOS): true deflected tip [m].
    spring_states_truth (sensor_msgs/JointState, SENSOR_QOS): true spring_1..spring_4
        deflections [rad] and torques [N·m].
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    tip_force_n (double[3]): external tip load [N], base frame; may change at runtime.
    rate_hz (double, read-only): simulation and publishing rate.
    initial_motor_positions_rad (double[3], read-only).
    motor.time_constant_s, motor.max_velocity_rad_s (double, read-only): motor response.
    noise.position_rad, noise.effort_nm (double): sensor noise.
    wrinkling (bool, read-only): saturate link moments at M_max (Table 3).
    seed (int, read-only): noise seed, -1 for a random one.
    frame_id (string, read-only): base frame.
"""

import dataclasses
import math

from geometry_msgs.msg import PointStamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState

from inflarm_hw.inflatable_arm_sim import ArmSimParams, InflatableArmSim
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    arm_from_parameters,
    check_arm_parameters,
)
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import COMMAND_QOS, SENSOR_QOS, subscription_events
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = ARM_PARAMETERS + (
    Parameter('tip_force_n', [0.0, 10.0, -15.0],
              'external tip load [N], base frame (default: the sample load of section 4)'),
    Parameter('rate_hz', 50.0, 'simulation and publishing rate [Hz]', range=(1.0, 1000.0),
              read_only=True),
    Parameter('initial_motor_positions_rad', [0.0, 0.6, -1.2],
              'joint_1..joint_3 at start [rad]', read_only=True),
    Parameter('motor.time_constant_s', 0.1, 'motor position time constant [s]',
              range=(0.001, 10.0), read_only=True),
    Parameter('motor.max_velocity_rad_s', 1.0, 'motor rate limit [rad/s]', range=(0.01, 100.0),
              read_only=True),
    Parameter('noise.position_rad', 1e-4, 'motor angle noise (std) [rad]', range=(0.0, 0.1)),
    Parameter('noise.effort_nm', 0.02, 'motor torque noise (std) [N m]', range=(0.0, 10.0)),
    Parameter('wrinkling', False, 'saturate link moments at M_max (Table 3)', read_only=True),
    Parameter('seed', -1, 'noise seed, -1 for a random one', range=(-1, 2**31 - 1),
              read_only=True),
    Parameter('frame_id', 'base_link', 'base frame', read_only=True),
)


def _three_finite(value) -> bool:
    return len(value) == 3 and all(math.isfinite(v) for v in value)


class ArmSim(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('arm_sim', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS)
        problem = check_arm_parameters(p) or next(
            (f'{name} must be 3 finite numbers' for name in
             ('tip_force_n', 'initial_motor_positions_rad') if not _three_finite(p[name])),
            None)
        if problem is not None:
            raise ValueError(problem)
        seed = p['seed']
        self.sim = InflatableArmSim(
            arm_from_parameters(p), p['arm.spring_stiffness'], p['arm.link_pressure_pa'],
            p['arm.link_radius_m'], p['initial_motor_positions_rad'],
            ArmSimParams(motor_time_constant=p['motor.time_constant_s'],
                         motor_max_velocity=p['motor.max_velocity_rad_s'],
                         position_noise=p['noise.position_rad'],
                         effort_noise=p['noise.effort_nm'], wrinkling=p['wrinkling']),
            np.random.default_rng(None if seed < 0 else seed))
        self.sim.set_tip_force(p['tip_force_n'])
        self.dt = 1.0 / p['rate_hz']

        self.create_subscription(
            JointState, 'motor_position_command', self.on_command, COMMAND_QOS,
            event_callbacks=subscription_events(self, 'motor_position_command'))
        self.joint_state_pub = self.create_publisher(JointState, 'joint_states', SENSOR_QOS)
        self.tip_pub = self.create_publisher(PointStamped, 'tip_position_truth', SENSOR_QOS)
        self.spring_pub = self.create_publisher(JointState, 'spring_states_truth', SENSOR_QOS)
        self.create_timer(self.dt, self.step)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(self.on_parameters_set)
        self.get_logger().info(f"ready: tip load {p['tip_force_n']} N at {p['rate_hz']} Hz")

    def on_set_parameters(self, parameters) -> SetParametersResult:
        values = {q.name: q.value for q in parameters}
        problem = check_arm_parameters(values)
        if problem is None and 'tip_force_n' in values and not _three_finite(
                values['tip_force_n']):
            problem = f"tip_force_n must be 3 finite numbers, got {values['tip_force_n']}"
        return SetParametersResult(successful=problem is None, reason=problem or '')

    def on_parameters_set(self, parameters) -> None:
        for q in parameters:
            self.params[q.name] = q.value
            if q.name == 'tip_force_n':
                self.sim.set_tip_force(q.value)
                self.get_logger().info(f'tip load now {list(q.value)} N')
            elif q.name == 'arm.spring_stiffness':
                self.sim.set_stiffness(q.value)
            elif q.name == 'arm.link_pressure_pa':
                self.sim.set_link_pressure(q.value)
            elif q.name.startswith('noise.'):
                field = {'noise.position_rad': 'position_noise',
                         'noise.effort_nm': 'effort_noise'}[q.name]
                self.sim.params = dataclasses.replace(self.sim.params, **{field: q.value})

    def on_command(self, msg: JointState) -> None:
        names = FlexibleArm.MOTOR_JOINT_NAMES
        unknown = sorted(set(msg.name) - set(names))
        if (unknown or len(msg.position) != len(msg.name)
                or not all(math.isfinite(v) for v in msg.position)):
            self.get_logger().warning(
                f'motor_position_command rejected: expected finite positions of {list(names)},'
                f' got {list(msg.name)} = {list(msg.position)}', throttle_duration_sec=2.0)
            return
        target = self.sim.target.copy()
        for name, position in zip(msg.name, msg.position, strict=True):
            target[names.index(name)] = position
        self.sim.command(target)

    def step(self) -> None:
        try:
            state = self.sim.step(self.dt)
        except RuntimeError as err:  # no equilibrium: hold the last state, say why
            self.get_logger().error(str(err), throttle_duration_sec=2.0)
            return
        stamp = self.get_clock().now().to_msg()
        joints = JointState(name=list(FlexibleArm.MOTOR_JOINT_NAMES),
                            position=state.q_m.tolist(), velocity=state.dq_m.tolist(),
                            effort=state.tau_m.tolist())
        joints.header.stamp = stamp
        self.joint_state_pub.publish(joints)
        springs = JointState(name=list(FlexibleArm.SPRING_JOINT_NAMES),
                             position=state.q_k.tolist(),
                             effort=(self.sim.stiffness * state.q_k).tolist())
        springs.header.stamp = stamp
        self.spring_pub.publish(springs)
        tip = PointStamped()
        tip.header.stamp = stamp
        tip.header.frame_id = self.params['frame_id']
        tip.point.x, tip.point.y, tip.point.z = state.tip_position.tolist()
        self.tip_pub.publish(tip)


def main(args: list[str] | None = None) -> None:
    spin_node(ArmSim, args)


if __name__ == '__main__':
    main()
