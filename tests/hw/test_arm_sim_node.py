"""arm_sim in-process: joint states carry the motor torques; commands, limits, the command
watchdog and runtime load changes."""

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from inflarm_hw.nodes.arm_sim import ArmSim
from inflarm_hw.realtime import ElapsedSteps
from inflarm_model.elastostatics import motor_torques
from inflarm_model.kinematics import FlexibleArm
from inflarm_msgs_json.ros.qos import COMMAND_QOS, SENSOR_QOS
from ros_harness import spin_until

NOISELESS = [Parameter('noise.position_rad', value=0.0), Parameter('noise.effort_nm', value=0.0)]


class Probe:
    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.sim = ArmSim(context=executor.context, parameter_overrides=NOISELESS + [
            Parameter(k, value=v) for k, v in overrides.items()])
        self.node = rclpy.create_node('probe', context=executor.context)
        self.joints: list[JointState] = []
        self.springs: list[JointState] = []
        # A default subscription (reliable, depth 10), as robot_state_publisher makes.
        self.node.create_subscription(JointState, 'joint_states', self.joints.append, 10)
        self.node.create_subscription(JointState, 'spring_states_truth', self.springs.append,
                                      SENSOR_QOS)
        self.command_pub = self.node.create_publisher(
            JointState, 'motor_position_command', COMMAND_QOS)
        executor.add_node(self.sim)
        executor.add_node(self.node)
        assert spin_until(executor, lambda: len(self.joints) >= 2)

    def wait_new(self, count: int = 3) -> JointState:
        start = len(self.joints)
        assert spin_until(self.executor, lambda: len(self.joints) >= start + count)
        return self.joints[-1]


def test_effort_is_the_torque_the_motors_apply_to_hold_the_load(executor):
    probe = Probe(executor)
    msg = probe.wait_new()
    assert list(msg.name) == ['joint_1', 'joint_2', 'joint_3']
    spring = probe.springs[-1]
    q = FlexibleArm.assemble_q(msg.position, spring.position)
    load_torques = motor_torques(FlexibleArm(0.6, 0.03), q, [0.0, 10.0, -15.0])  # eq. 6
    np.testing.assert_allclose(msg.effort, -load_torques, atol=1e-6)
    assert np.abs(spring.position).max() > 1e-3  # the default load bends the links


def test_commands_move_the_motors_and_bad_ones_are_rejected(executor):
    # Not the command watchdog's test: at its default 1 s, on a busy machine (load average 14)
    # the motors were held short of the last command before reaching it.
    probe = Probe(executor, cmd_timeout_s=5.0)
    probe.command_pub.publish(JointState(name=['joint_1'], position=[float('nan')]))
    probe.command_pub.publish(JointState(name=['elbow'], position=[0.3]))
    probe.wait_new(5)
    np.testing.assert_allclose(probe.sim.sim.target, [0.0, 0.6, -1.2])

    # Finite but beyond the joint limits: rejected whole, the other joint does not move either.
    probe.command_pub.publish(JointState(name=['joint_1', 'joint_2'], position=[100.0, 0.5]))
    probe.wait_new(5)
    np.testing.assert_allclose(probe.sim.sim.target, [0.0, 0.6, -1.2])
    assert 'joint_1 at 100 rad is outside its limits' in \
        probe.sim.problems.last['motor_position_command']

    probe.command_pub.publish(JointState(name=['joint_1', 'joint_3'], position=[0.2, -1.0]))
    assert spin_until(executor, lambda: abs(probe.joints[-1].position[0] - 0.2) < 1e-4,
                      timeout_s=10.0)
    np.testing.assert_allclose(probe.joints[-1].position, [0.2, 0.6, -1.0], atol=1e-4)
    assert probe.sim.problems.unexpected == 0


def test_without_commands_the_motors_hold_where_they_are(executor):
    probe = Probe(executor, cmd_timeout_s=0.3, **{'motor.max_velocity_rad_s': 0.2})
    probe.command_pub.publish(JointState(name=['joint_1'], position=[1.0]))
    assert spin_until(executor, lambda: probe.joints[-1].position[0] > 0.02)
    # The controller falls silent: after cmd_timeout_s the motor stops short of 1 rad.
    assert spin_until(executor, lambda: probe.sim.last_command_time is None, timeout_s=5.0)
    held = probe.sim.sim.target[0]
    assert 0.02 < held < 0.5
    probe.wait_new(10)
    assert abs(probe.joints[-1].position[0] - held) < 1e-3


def test_the_tip_load_changes_at_runtime_and_bad_loads_are_rejected(executor):
    probe = Probe(executor)
    bad = probe.sim.set_parameters([Parameter('tip_force_n', value=[1.0, float('nan'), 0.0])])
    assert not bad[0].successful and 'tip_force_n' in bad[0].reason
    assert probe.sim.set_parameters([Parameter('tip_force_n', value=[0.0, 0.0, 0.0])])[0] \
        .successful
    msg = probe.wait_new()
    np.testing.assert_allclose(msg.effort, 0.0, atol=1e-9)
    np.testing.assert_allclose(probe.springs[-1].position, 0.0, atol=1e-9)


def test_inconsistent_parameters_fail_at_startup(ros_context):
    with pytest.raises(ValueError, match='initial_motor_positions_rad'):
        ArmSim(context=ros_context, parameter_overrides=[
            Parameter('initial_motor_positions_rad', value=[0.0, 1.0])])


def test_a_late_step_simulates_the_time_that_passed(ros_context):
    """A host stall of 0.3 s: the next step moves the arm on by 0.3 s, not one period, so it
    stays with the time-stamped set points (ramped by their velocity) instead of falling behind."""
    sim = ArmSim(context=ros_context, parameter_overrides=NOISELESS + [
        Parameter('motor.time_constant_s', value=0.02)])
    try:
        clock = [0.0]
        sim.elapsed = ElapsedSteps(max_step_s=0.5, clock=lambda: clock[0])
        sim.sim.command(sim.sim.q_m, [0.5, 0.0, 0.0])  # joint_1 ramps at 0.5 rad/s
        start = sim.sim.time
        clock[0] = 0.3
        sim.step()
        assert sim.sim.time - start == pytest.approx(0.3)
        assert sim.sim.target[0] == pytest.approx(0.15)
        clock[0] = 10.0  # a suspended process: at most 0.5 s is simulated
        sim.step()
        assert sim.sim.time - start == pytest.approx(0.8)
        # The controller was not stalled: its set point, stamped 0.3 s after the last step,
        # is where the target is once the simulator has caught up with that time.
        stamp = Time(nanoseconds=sim.last_step_ns + 300_000_000)
        sim.on_command(JointState(header=Header(stamp=stamp.to_msg()), name=['joint_1'],
                                  position=[0.4], velocity=[0.5]))
        clock[0] = 10.3
        sim.step()
        assert sim.sim.target[0] == pytest.approx(0.4)
    finally:
        sim.destroy_node()
