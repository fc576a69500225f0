"""The simulated inflatable arm: motor lag, elastostatic equilibrium, wrinkling saturation."""

import numpy as np
import pytest

from inflarm_hw.inflatable_arm_sim import ArmSimParams, InflatableArmSim, max_moment
from inflarm_model.elastostatics import spring_torques
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.link import MEAN_STIFFNESS, TABLE3, wrinkling_moment

ARM = FlexibleArm(0.6, 0.03)
Q_M0 = np.array([0.3, 0.6, -1.2])
FORCE = np.array([0.0, 10.0, -15.0])  # the paper's sample load, section 4


def make_sim(**params) -> InflatableArmSim:
    return InflatableArmSim(ARM, MEAN_STIFFNESS, [50e3, 50e3], 0.055, Q_M0,
                            ArmSimParams(**params), np.random.default_rng(7))


def test_unloaded_arm_is_the_rigid_arm_with_zero_torques():
    state = make_sim().step(0.01)
    np.testing.assert_allclose(state.q_k, 0.0, atol=1e-12)
    np.testing.assert_allclose(state.tau_m, 0.0, atol=1e-12)
    rigid_tip = ARM.fk(FlexibleArm.assemble_q(Q_M0, np.zeros(4)))[:3, 3]
    np.testing.assert_allclose(state.tip_position, rigid_tip, atol=1e-12)


def test_a_tip_load_deflects_the_links_at_equilibrium():
    sim = make_sim()
    unloaded_tip = sim.state().tip_position
    sim.set_tip_force(FORCE)
    state = sim.step(0.01)
    q = FlexibleArm.assemble_q(state.q_m, state.q_k)
    # eq. (7): every spring holds the load torque on its axis
    np.testing.assert_allclose(MEAN_STIFFNESS * state.q_k, spring_torques(ARM, q, FORCE),
                               atol=1e-8)
    # eq. (6): the reported motor torques are the load torques on the motor axes
    U = ARM.jacobian(q)[:3]
    np.testing.assert_allclose(state.tau_m, U[:, [0, 1, 4]].T @ FORCE, atol=1e-12)
    deflection = state.tip_position - unloaded_tip
    assert deflection @ FORCE > 0.0  # the tip gives way along the load
    assert 0.01 < np.linalg.norm(deflection) < 0.2  # 18 N at ~1 m on k = 172.71 N·m/rad


def test_motors_follow_commands_with_a_rate_limit():
    sim = make_sim(motor_time_constant=0.05, motor_max_velocity=0.5)
    target = Q_M0 + [0.4, -0.2, 0.1]
    sim.command(target)
    previous = sim.q_m.copy()
    for _ in range(300):
        state = sim.step(0.01)
        assert np.all(np.abs(state.q_m - previous) <= 0.5 * 0.01 + 1e-12)
        previous = state.q_m
    np.testing.assert_allclose(state.q_m, target, atol=1e-6)


def test_wrinkling_holds_a_link_moment_at_m_max():
    pressure = 10e3  # M_w = 4.11 N·m: the sample load bends link 1 well beyond it
    plain = InflatableArmSim(ARM, MEAN_STIFFNESS, [pressure, pressure], 0.055, Q_M0)
    plain.set_tip_force(FORCE)
    over = plain.step(0.01).link_moments
    m_max = max_moment(pressure, 0.055)
    assert over[0] > m_max

    sim = InflatableArmSim(ARM, MEAN_STIFFNESS, [pressure, pressure], 0.055, Q_M0,
                           ArmSimParams(wrinkling=True))
    sim.set_tip_force(FORCE)
    state = sim.step(0.01)
    assert state.wrinkled[0]
    assert state.link_moments[0] == pytest.approx(m_max, rel=2e-4)
    # the yielding link deflects more than the elastic one would
    assert np.linalg.norm(state.q_k[:2]) > np.linalg.norm(plain.q_k[:2])


def test_max_moment_follows_table3():
    for row in TABLE3:
        if row.max_moment is not None:
            ratio = row.max_moment / row.wrinkling_moment
            assert max_moment(row.pressure, 0.055) == pytest.approx(
                ratio * wrinkling_moment(row.pressure, 0.055))


@pytest.mark.parametrize('call, match', [
    (lambda s: s.command([0.0, np.nan, 0.0]), 'q_m as 3 finite numbers'),
    (lambda s: s.set_tip_force([1.0, 2.0]), 'force as 3 finite numbers'),
    (lambda s: s.set_link_pressure([50e3, -1.0]), 'link_pressure > 0'),
    (lambda s: s.set_stiffness([1.0, 2.0]), 'stiffness'),
    (lambda s: s.step(0.0), 'dt > 0'),
])
def test_bad_input_is_rejected_and_the_state_kept(call, match):
    sim = make_sim()
    before = sim.state()
    with pytest.raises(ValueError, match=match):
        call(sim)
    np.testing.assert_array_equal(sim.target, Q_M0)
    np.testing.assert_array_equal(sim.force, 0.0)
    assert sim.time == before.time


def test_targets_are_clamped_to_the_urdf_motor_limits():
    from inflarm_model.urdf import JOINT_LIMITS

    limits = [JOINT_LIMITS[name] for name in FlexibleArm.MOTOR_JOINT_NAMES]
    sim = make_sim(motor_time_constant=0.01, motor_max_velocity=10.0)
    sim.command([4.0, -2.0, 3.0])
    np.testing.assert_array_equal(sim.target, [limits[0][1], limits[1][0], limits[2][1]])
    for _ in range(200):
        state = sim.step(0.01)
    np.testing.assert_allclose(state.q_m, sim.target, atol=1e-9)
    with pytest.raises(ValueError, match='within the motor limits'):
        InflatableArmSim(ARM, MEAN_STIFFNESS, [50e3, 50e3], 0.055, [0.0, 2.0, 0.0])
