"""Tests of inflarm_model.elastostatics: spring equilibrium under a tip load, eqs (5)-(7).

The independent reference is the textbook DH chain of ``inflarm_model.kinematics``
(``dh_jacobian_reference``, per-joint 4x4 products, no Pinocchio) solved with
``scipy.optimize.root``; finite differences check the Hessian and the virtual-work sign.
"""

import numpy as np
import pytest

from elastostatic_reference import K_MEAN, K, M, full_q, reference_deflections
from inflarm_model.elastostatics import (
    check_stiffness,
    link_moments,
    load_hessian,
    motor_torques,
    motor_torques_batch,
    spring_deflections,
    spring_deflections_batch,
    spring_torques,
)
from inflarm_model.kinematics import (
    FlexibleArm,
    RigidArm,
    dh_fk_reference,
    dh_frames_reference,
    dh_jacobian_reference,
)


@pytest.fixture(scope='module')
def arm():
    return FlexibleArm()








def random_load(rng, f_max):
    d = rng.normal(size=3)
    return d / np.linalg.norm(d) * rng.uniform(0.0, f_max)


def test_deflections_match_an_independent_solver_up_to_100_n_per_spring_stiffness(arm):
    rng = np.random.default_rng(7)
    for _ in range(25):
        q_m = rng.uniform(-np.pi, np.pi, 3)
        force = random_load(rng, 100.0)
        k = rng.uniform(150.0, 190.0, 4)  # the two springs of a link may differ
        result = spring_deflections(arm, q_m, force, k)
        assert result.converged, result.status
        assert result.residual <= 1e-9
        expected = reference_deflections(arm, q_m, force, k, max_residual=1e-9)
        np.testing.assert_allclose(result.q_k, expected, atol=1e-9, rtol=0)
        np.testing.assert_allclose(result.tau_k, k * result.q_k, rtol=1e-15)
        np.testing.assert_allclose(
            result.tip_position,
            dh_fk_reference(arm.dh_table, full_q(q_m, result.q_k))[:3, 3], atol=1e-12)


def test_a_force_deflects_the_tip_along_itself(arm):
    # The documented sign: k q_k = U_k^T f, so the springs give way in the direction of f.
    rng = np.random.default_rng(7)
    for _ in range(20):
        q_m = rng.uniform(-np.pi, np.pi, 3)
        force = random_load(rng, 30.0)
        result = spring_deflections(arm, q_m, force, K_MEAN)
        rigid_tip = arm.fk(full_q(q_m, np.zeros(4)))[:3, 3]
        assert np.dot(result.tip_position - rigid_tip, force) > 0.0


def test_small_loads_give_the_linear_compliance(arm):
    rng = np.random.default_rng(7)
    q_m = rng.uniform(-1.0, 1.0, 3)
    force = np.array([0.02, -0.01, 0.03])
    U = dh_jacobian_reference(arm.dh_table, full_q(q_m, np.zeros(4)))[:3]
    result = spring_deflections(arm, q_m, force, K_MEAN)
    np.testing.assert_allclose(result.q_k, U[:, K].T @ force / K_MEAN, rtol=1e-3)


def test_motor_torques_are_the_virtual_work_of_the_load(arm):
    # tau_m = U_m^T f = d(f . p_e)/dq_m, by central differences of the textbook FK.
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.0, 1.0, 7)
    force = rng.normal(size=3) * 20.0
    h = 1e-6
    expected = []
    for i in M:
        dq = np.zeros(7)
        dq[i] = h
        plus = dh_fk_reference(arm.dh_table, q + dq)[:3, 3]
        minus = dh_fk_reference(arm.dh_table, q - dq)[:3, 3]
        expected.append(force @ (plus - minus) / (2.0 * h))
    np.testing.assert_allclose(motor_torques(arm, q, force), expected, atol=1e-7)


def test_load_hessian_matches_finite_differences(arm):
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.0, 1.0, 7)
    force = rng.normal(size=3) * 30.0
    h = 1e-6
    numeric = np.empty((7, 7))
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        plus = dh_jacobian_reference(arm.dh_table, q + dq)[:3].T @ force
        minus = dh_jacobian_reference(arm.dh_table, q - dq)[:3].T @ force
        numeric[:, i] = (plus - minus) / (2.0 * h)
    H = load_hessian(arm, q, force)
    np.testing.assert_allclose(H, H.T, atol=1e-12)
    np.testing.assert_allclose(H, numeric, atol=1e-7)


def test_link_moment_is_the_bending_part_of_the_moment_at_the_springs(arm):
    # Link 2's springs (DH joints 6, 7) share the origin of DH frame 5; their orthogonal axes
    # z_5 and z_6 span the bending plane, so sqrt(tau_6^2 + tau_7^2) is the moment of f about
    # that point with its component along the link (torsion, not carried) removed.
    rng = np.random.default_rng(7)
    q_m = rng.uniform(-1.0, 1.0, 3)
    force = np.array([0.0, 10.0, -15.0])
    result = spring_deflections(arm, q_m, force, K_MEAN)
    q = full_q(q_m, result.q_k)
    frames = dh_frames_reference(arm.dh_table, q)
    tip = frames[-1][:3, 3]
    for link, (a, b) in ((0, (2, 3)), (1, (5, 6))):
        origin = frames[a][:3, 3]
        moment = np.cross(tip - origin, force)
        za, zb = frames[a][:3, 2], frames[b][:3, 2]
        assert abs(za @ zb) < 1e-12
        expected = np.hypot(moment @ za, moment @ zb)
        assert link_moments(arm, q, force)[link] == pytest.approx(expected, abs=1e-12)
    # At equilibrium the springs carry it: k q_k.
    np.testing.assert_allclose(link_moments(arm, q, force),
                               np.hypot(result.tau_k[[0, 2]], result.tau_k[[1, 3]]), atol=1e-8)


def test_stiffer_springs_deflect_less(arm):
    q_m = np.array([0.2, 0.4, -0.9])
    force = np.array([0.0, 10.0, -15.0])
    soft = spring_deflections(arm, q_m, force, K_MEAN)
    stiff_link2 = spring_deflections(arm, q_m, force, [K_MEAN, K_MEAN, 1e7, 1e7])
    assert np.abs(stiff_link2.q_k[2:]).max() < 1e-4
    assert np.abs(stiff_link2.q_k[2:]).max() < 1e-3 * np.abs(soft.q_k[2:]).max()


def test_unstable_equilibrium_is_reported(arm):
    # Straight arm along x, pushed back along its axis: q_k = 0 balances any such force, but
    # beyond the buckling load (~150 N here) it is unstable.
    straight = np.zeros(3)
    light = spring_deflections(arm, straight, [-50.0, 0.0, 0.0], K_MEAN)
    assert light.converged
    np.testing.assert_array_equal(light.q_k, 0.0)
    heavy = spring_deflections(arm, straight, [-400.0, 0.0, 0.0], K_MEAN)
    assert not heavy.converged
    assert heavy.status == 'unstable'
    assert np.isnan(heavy.q_k).all() and np.isnan(heavy.tip_position).all()
    batch = spring_deflections_batch(arm, [straight, straight], [[-50.0, 0, 0], [-400.0, 0, 0]],
                                     K_MEAN)
    assert batch.status.tolist() == ['converged', 'unstable']


def test_non_convergence_is_reported(arm):
    result = spring_deflections(arm, [0.3, 0.8, -1.2], [40.0, 30.0, -60.0], K_MEAN,
                                max_iterations=1)
    assert not result.converged
    assert result.status == 'max_iterations'
    assert result.iterations == 1
    assert result.residual > 1e-9
    assert np.isnan(result.q_k).all()


def test_warm_start_converges_in_fewer_iterations(arm):
    q_m = np.array([0.3, 0.8, -1.2])
    force = np.array([0.0, 10.0, -15.0])
    cold = spring_deflections(arm, q_m, force, K_MEAN)
    warm = spring_deflections(arm, q_m + 0.01, force, K_MEAN, q_k0=cold.q_k)
    assert warm.converged and warm.iterations < cold.iterations


def test_batch_equals_single(arm):
    rng = np.random.default_rng(7)
    Q_m = rng.uniform(-np.pi, np.pi, (40, 3))
    forces = rng.normal(size=(40, 3)) * 25.0
    k = [170.0, 175.0, 160.0, 180.0]
    batch = spring_deflections_batch(arm, Q_m, forces, k)
    for i in range(40):
        one = spring_deflections(arm, Q_m[i], forces[i], k)
        assert batch.status[i] == one.status
        np.testing.assert_allclose(batch.q_k[i], one.q_k, atol=1e-11)
        np.testing.assert_allclose(batch.tip_position[i], one.tip_position, atol=1e-11)
    Q = np.hstack([Q_m, np.zeros((40, 4))])[:, [0, 1, 3, 4, 2, 5, 6]]
    Q[:, K] = batch.q_k
    expected = np.array([motor_torques(arm, Q[i], forces[i]) for i in range(40)])
    np.testing.assert_allclose(motor_torques_batch(arm, Q, forces), expected, atol=1e-12)
    np.testing.assert_allclose(spring_torques(arm, Q, forces), batch.tau_k, atol=1e-8)
    np.testing.assert_allclose(link_moments(arm, Q, forces)[7], link_moments(arm, Q[7],
                                                                             forces[7]))


def test_stiffness_forms():
    assert check_stiffness(172.71) == (172.71,) * 4
    assert check_stiffness(170) == (170.0,) * 4
    assert check_stiffness(np.array([1.0, 2.0, 3.0, 4.0])) == (1.0, 2.0, 3.0, 4.0)


@pytest.mark.parametrize('stiffness, match', [
    (0.0, 'positive'), (-5.0, 'positive'), (np.nan, 'positive'), ([1.0, 2.0, 3.0], 'shape'),
    ([1.0, 2.0, -3.0, 4.0], 'positive'), ('stiff', 'stiffness'),
])
def test_bad_stiffness_raises(arm, stiffness, match):
    with pytest.raises(ValueError, match=match):
        spring_deflections(arm, np.zeros(3), np.zeros(3), stiffness)


@pytest.mark.parametrize('kwargs, match', [
    ({'q_m': [0.0, np.nan, 0.0]}, 'q_m'),
    ({'q_m': np.zeros(4)}, r'q_m of shape \(3,\)'),
    ({'force': [1.0, 2.0]}, r'force of shape \(3,\)'),
    ({'force': [1.0, np.inf, 0.0]}, 'force'),
    ({'q_k0': np.zeros(3)}, r'q_k0 of shape \(4,\)'),
    ({'tol': 0.0}, 'tol'),
    ({'max_iterations': 0}, 'max_iterations'),
])
def test_bad_input_raises(arm, kwargs, match):
    args = dict(q_m=np.zeros(3), force=np.zeros(3), stiffness=K_MEAN)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        spring_deflections(arm, **args)


def test_rigid_arm_is_refused():
    with pytest.raises(ValueError, match='FlexibleArm'):
        spring_deflections(RigidArm(), np.zeros(3), np.zeros(3), K_MEAN)


def test_batch_bad_input_raises(arm):
    with pytest.raises(ValueError, match=r'Q_m of shape \(N, 3\)'):
        spring_deflections_batch(arm, np.zeros((5, 2)), np.zeros(3), K_MEAN)
    with pytest.raises(ValueError, match='forces'):
        spring_deflections_batch(arm, np.zeros((5, 3)), np.zeros((4, 3)), K_MEAN)
    with pytest.raises(ValueError, match=r'q of shape \(7,\)'):
        motor_torques(arm, np.zeros(6), np.zeros(3))
