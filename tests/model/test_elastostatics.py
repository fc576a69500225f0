"""Tests of inflarm_model.elastostatics: eqs (4)-(7), the load Hessian, D and the Fig. 5 solvers.

The independent reference is the textbook DH chain of ``inflarm_model.kinematics``
(``dh_jacobian_reference``, per-joint 4x4 products, no Pinocchio, none of the compiled code)
solved with ``scipy.optimize.root``; finite differences check the Hessian, D and the signs.
"""

import dataclasses

import numpy as np
import pytest

from elastostatic_reference import K_MEAN, K, M, full_q, reference_deflections
from inflarm_model.elastostatics import (
    STATUS_NAMES,
    ElastostaticSolution,
    check_stiffness,
    equilibrium_stiffness,
    link_moments,
    load_hessian,
    load_torques,
    motor_load,
    motor_torques,
    reduced_newton_matrix,
    solve_load_continuation,
    solve_load_fixed_point,
    solve_load_newton,
    spring_deflections,
    spring_residual,
    spring_torques,
    stable,
    tip_position_and_jacobian,
)
from inflarm_model.kinematics import (
    FlexibleArm,
    RigidArm,
    dh_fk_reference,
    dh_frames_reference,
    dh_jacobian_reference,
)

KS = np.full(4, K_MEAN)


@pytest.fixture(scope='module')
def arm():
    return FlexibleArm()


def random_load(rng, f_max):
    d = rng.normal(size=3)
    return d / np.linalg.norm(d) * rng.uniform(0.0, f_max)


def random_motors(rng, n=None):
    shape = (3,) if n is None else (n, 3)
    return rng.uniform([-np.pi, -np.pi / 2, -2.6], [np.pi, np.pi / 2, 2.6], shape)


def reference_jacobian(arm, q):
    return dh_jacobian_reference(arm.dh_table, q)


# --- the equations ---------------------------------------------------------------------------


def test_tip_jacobian_is_eq_4_of_the_textbook_chain(arm):
    rng = np.random.default_rng(7)
    Q = rng.uniform(-2.0, 2.0, (2, 3, 7))
    p, J = tip_position_and_jacobian(arm, Q)
    assert p.shape == (2, 3, 3) and J.shape == (2, 3, 6, 7)
    for idx in np.ndindex(2, 3):
        np.testing.assert_allclose(J[idx], reference_jacobian(arm, Q[idx]), atol=1e-12)
        np.testing.assert_allclose(p[idx], dh_fk_reference(arm.dh_table, Q[idx])[:3, 3],
                                   atol=1e-12)


def test_load_torques_are_the_virtual_work_of_the_load(arm):
    # tau = U^T f = d(f . p_e)/dq (eqs 5-6), by central differences of the textbook FK.
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.0, 1.0, 7)
    force = rng.normal(size=3) * 20.0
    h = 1e-6
    expected = []
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        plus = dh_fk_reference(arm.dh_table, q + dq)[:3, 3]
        minus = dh_fk_reference(arm.dh_table, q - dq)[:3, 3]
        expected.append(force @ (plus - minus) / (2.0 * h))
    J = tip_position_and_jacobian(arm, q)[1]
    np.testing.assert_allclose(load_torques(J, force), expected, atol=1e-7)
    np.testing.assert_allclose(motor_torques(arm, q, force), np.array(expected)[M], atol=1e-7)
    np.testing.assert_allclose(spring_torques(arm, q, force), np.array(expected)[K], atol=1e-7)


def test_motor_load_inverts_eq_6(arm):
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.0, 1.0, (5, 7))
    forces = rng.normal(size=(5, 3)) * 30.0
    J = tip_position_and_jacobian(arm, q)[1]
    np.testing.assert_allclose(motor_load(J, load_torques(J, forces)[:, M]), forces, atol=1e-9)
    # Singular U_m (stretched straight up along the first axis): not finite, no exception.
    J = tip_position_and_jacobian(arm, full_q([0.3, np.pi / 2, 0.0], np.zeros(4)))[1]
    J[:, 0] = 0.0  # exactly singular
    assert not np.isfinite(motor_load(J, [1.0, 2.0, 3.0])).all()


def test_spring_residual_is_eq_7(arm):
    rng = np.random.default_rng(7)
    q, f = rng.uniform(-1.0, 1.0, 7), rng.normal(size=3) * 10.0
    U = reference_jacobian(arm, q)[:3]
    J = tip_position_and_jacobian(arm, q)[1]
    np.testing.assert_allclose(spring_residual(J, f, q[K], KS), K_MEAN * q[K] - U[:, K].T @ f,
                               atol=1e-12)


def test_load_hessian_matches_finite_differences(arm):
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.0, 1.0, 7)
    force = rng.normal(size=3) * 30.0
    h = 1e-6
    numeric = np.empty((7, 7))
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        plus = reference_jacobian(arm, q + dq)[:3].T @ force
        minus = reference_jacobian(arm, q - dq)[:3].T @ force
        numeric[:, i] = (plus - minus) / (2.0 * h)
    H = load_hessian(tip_position_and_jacobian(arm, q)[1], force)
    np.testing.assert_allclose(H, H.T, atol=1e-12)
    np.testing.assert_allclose(H, numeric, atol=1e-7)
    np.testing.assert_allclose(equilibrium_stiffness(H, KS),
                               np.diag(KS) - H[np.ix_(K, K)], atol=1e-12)


def test_reduced_newton_matrix_is_the_derivative_of_the_reduced_residual(arm):
    # g(q_k) = K q_k - U_k^T f(q_k), f(q_k) = U_m^-T tau_m, by central differences on the
    # textbook chain.
    rng = np.random.default_rng(7)
    q_m, q_k = rng.uniform(-1.0, 1.0, 3), rng.uniform(-0.3, 0.3, 4)
    tau_m = np.array([5.0, -12.0, 7.0])

    def g(x):
        U = reference_jacobian(arm, full_q(q_m, x))[:3]
        return K_MEAN * x - U[:, K].T @ np.linalg.solve(U[:, M].T, tau_m)

    h = 1e-6
    numeric = np.array([(g(q_k + h * e) - g(q_k - h * e)) / (2 * h) for e in np.eye(4)]).T
    J = tip_position_and_jacobian(arm, full_q(q_m, q_k))[1]
    D = reduced_newton_matrix(J, load_hessian(J, motor_load(J, tau_m)), KS)
    np.testing.assert_allclose(D, numeric, atol=1e-6)


def test_equations_broadcast_and_a_single_call_is_a_batch_of_one(arm):
    rng = np.random.default_rng(7)
    Q = rng.uniform(-1.0, 1.0, (4, 2, 7))
    F = rng.normal(size=(4, 2, 3)) * 20.0
    J = tip_position_and_jacobian(arm, Q)[1]
    H = load_hessian(J, F)
    outputs = {
        'load_torques': load_torques(J, F), 'motor_load': motor_load(J, F),
        'load_hessian': H, 'equilibrium_stiffness': equilibrium_stiffness(H, KS),
        'reduced_newton_matrix': reduced_newton_matrix(J, H, KS), 'stable': stable(H, KS),
        'spring_residual': spring_residual(J, F, Q[..., K], KS),
        'motor_torques': motor_torques(arm, Q, F), 'link_moments': link_moments(arm, Q, F),
    }
    for idx in np.ndindex(4, 2):
        j, f, q = J[idx], F[idx], Q[idx]
        single = {
            'load_torques': load_torques(j, f), 'motor_load': motor_load(j, f),
            'load_hessian': load_hessian(j, f),
            'equilibrium_stiffness': equilibrium_stiffness(load_hessian(j, f), KS),
            'reduced_newton_matrix': reduced_newton_matrix(j, load_hessian(j, f), KS),
            'stable': stable(load_hessian(j, f), KS),
            'spring_residual': spring_residual(j, f, q[K], KS),
            'motor_torques': motor_torques(arm, q, f), 'link_moments': link_moments(arm, q, f),
        }
        for name, value in single.items():
            np.testing.assert_array_equal(outputs[name][idx], value, err_msg=name)
    # One force for many configurations.
    np.testing.assert_allclose(motor_torques(arm, Q, F[0, 0]),
                               motor_torques(arm, Q, np.broadcast_to(F[0, 0], (4, 2, 3))))


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
    np.testing.assert_allclose(link_moments(arm, q, force),
                               np.hypot(result.tau_k[[0, 2]], result.tau_k[[1, 3]]), atol=1e-8)


# --- forward problem -------------------------------------------------------------------------


def test_deflections_match_an_independent_solver_up_to_100_n_per_spring_stiffness(arm):
    rng = np.random.default_rng(7)
    for _ in range(25):
        q_m = rng.uniform(-np.pi, np.pi, 3)
        force = random_load(rng, 100.0)
        k = rng.uniform(150.0, 190.0, 4)  # the two springs of a link may differ
        result = spring_deflections(arm, q_m, force, k)
        assert result.converged, result.status
        assert result.residual <= 1e-10
        expected = reference_deflections(arm, q_m, force, k, max_residual=1e-9)
        np.testing.assert_allclose(result.q_k, expected, atol=1e-9, rtol=0)
        np.testing.assert_allclose(result.tau_k, k * result.q_k, rtol=1e-15)
        q = full_q(q_m, result.q_k)
        np.testing.assert_allclose(result.tip_position,
                                   dh_fk_reference(arm.dh_table, q)[:3, 3], atol=1e-12)
        np.testing.assert_allclose(result.jacobian, reference_jacobian(arm, q), atol=1e-12)
        np.testing.assert_array_equal(result.force, force)


def test_a_force_deflects_the_tip_along_itself(arm):
    # The documented sign: k q_k = U_k^T f, so the springs give way in the direction of f.
    rng = np.random.default_rng(7)
    q_m = rng.uniform(-np.pi, np.pi, (20, 3))
    forces = np.array([random_load(rng, 30.0) for _ in range(20)])
    result = spring_deflections(arm, q_m, forces, K_MEAN)
    rigid = tip_position_and_jacobian(arm, np.array([full_q(m, np.zeros(4)) for m in q_m]))[0]
    assert (np.einsum('ij,ij->i', result.tip_position - rigid, forces) > 0.0).all()


def test_small_loads_give_the_linear_compliance(arm):
    rng = np.random.default_rng(7)
    q_m = rng.uniform(-1.0, 1.0, 3)
    force = np.array([0.02, -0.01, 0.03])
    U = reference_jacobian(arm, full_q(q_m, np.zeros(4)))[:3]
    result = spring_deflections(arm, q_m, force, K_MEAN)
    np.testing.assert_allclose(result.q_k, U[:, K].T @ force / K_MEAN, rtol=1e-3)


def test_stiffer_springs_deflect_less(arm):
    q_m = np.array([0.2, 0.4, -0.9])
    force = np.array([0.0, 10.0, -15.0])
    soft = spring_deflections(arm, q_m, force, K_MEAN)
    stiff_link2 = spring_deflections(arm, q_m, force, [K_MEAN, K_MEAN, 1e7, 1e7])
    assert np.abs(stiff_link2.q_k[2:]).max() < 1e-3 * np.abs(soft.q_k[2:]).max()


def test_unstable_equilibrium_is_reported(arm):
    # Straight arm along x, pushed back along its axis: q_k = 0 balances any such force, but
    # beyond the buckling load (~150 N here) it is unstable.
    straight = np.zeros(3)
    light = spring_deflections(arm, straight, [-50.0, 0.0, 0.0], K_MEAN)
    assert light.converged
    np.testing.assert_array_equal(light.q_k, 0.0)
    heavy = spring_deflections(arm, straight, [-400.0, 0.0, 0.0], K_MEAN)
    assert not heavy.converged and heavy.status == 'unstable'
    assert np.isnan(heavy.q_k).all() and np.isnan(heavy.tip_position).all()
    batch = spring_deflections(arm, [straight, straight], [[-50.0, 0, 0], [-400.0, 0, 0]],
                               K_MEAN)
    assert batch.status.tolist() == ['converged', 'unstable']


def test_non_convergence_is_reported(arm):
    result = spring_deflections(arm, [0.3, 0.8, -1.2], [40.0, 30.0, -60.0], K_MEAN,
                                max_iterations=1)
    assert not result.converged
    assert result.status == 'max_iterations'
    assert result.iterations == 1
    assert result.residual > 1e-9
    assert np.isnan(result.q_k).all() and np.isnan(result.jacobian).all()


def test_warm_start_converges_in_fewer_iterations(arm):
    q_m = np.array([0.3, 0.8, -1.2])
    force = np.array([0.0, 10.0, -15.0])
    cold = spring_deflections(arm, q_m, force, K_MEAN)
    warm = spring_deflections(arm, q_m + 0.01, force, K_MEAN, q_k0=cold.q_k)
    assert warm.converged and warm.iterations < cold.iterations


# --- inverse problem: the solvers of Fig. 5 -------------------------------------------------


def loaded(arm, q_m, force, k=K_MEAN):
    q_k = reference_deflections(arm, q_m, force, k, max_residual=1e-10)
    return q_k, reference_jacobian(arm, full_q(q_m, q_k))[:3, M].T @ force


@pytest.mark.parametrize('solver', [solve_load_newton, solve_load_fixed_point,
                                    solve_load_continuation])
def test_inverse_solvers_recover_a_moderate_load(arm, solver):
    q_m = np.array([0.3, 0.9, -1.4])
    force = np.array([0.0, 10.0, -15.0])  # f_e of section 4
    q_k, tau_m = loaded(arm, q_m, force)
    result = solver(arm, q_m, tau_m, K_MEAN)
    assert isinstance(result, ElastostaticSolution) and result.status == 'converged'
    assert result.residual <= 1e-10
    np.testing.assert_allclose(result.force, force, atol=1e-9)
    np.testing.assert_allclose(result.q_k, q_k, atol=1e-11)


def test_newton_needs_fewer_steps_than_the_fixed_point(arm):
    q_m = np.array([-0.4, 0.5, 1.1])
    q_k, tau_m = loaded(arm, q_m, np.array([3.0, -2.0, 4.0]))
    paper = solve_load_fixed_point(arm, q_m, tau_m, K_MEAN)
    newton = solve_load_newton(arm, q_m, tau_m, K_MEAN)
    assert paper.converged and newton.converged
    assert newton.iterations < paper.iterations
    np.testing.assert_allclose(paper.force, newton.force, atol=1e-8)


def test_fixed_point_of_fig_5_diverges_where_newton_converges(arm):
    rng = np.random.default_rng(7)
    Q_m = random_motors(rng, 300)
    forces = np.array([random_load(rng, 80.0) for _ in range(300)])
    big = np.linalg.norm(forces, axis=1) >= 50.0
    eq = spring_deflections(arm, Q_m[big], forces[big], K_MEAN)
    q = np.array([full_q(m, k) for m, k in zip(Q_m[big], eq.q_k, strict=True)])
    tau = motor_torques(arm, q, forces[big])
    paper = solve_load_fixed_point(arm, Q_m[big], tau, K_MEAN)
    newton = solve_load_newton(arm, Q_m[big], tau, K_MEAN)
    exact = newton.converged & (np.abs(newton.force - forces[big]).max(axis=1) < 1e-6)
    fails = exact & ~paper.converged
    assert fails.sum() >= 3, fails.sum()  # 5-10 % of loads of 50-80 N
    assert set(paper.status[fails]) <= {'diverged', 'max_iterations'}
    assert np.isnan(paper.force[fails]).all()


def test_continuation_follows_the_unloaded_branch(arm):
    rng = np.random.default_rng(7)
    Q_m = random_motors(rng, 40)
    forces = np.array([random_load(rng, 60.0) for _ in range(40)])
    eq = spring_deflections(arm, Q_m, forces, K_MEAN)
    q = np.array([full_q(m, k) for m, k in zip(Q_m, eq.q_k, strict=True)])
    result = solve_load_continuation(arm, Q_m, motor_torques(arm, q, forces), K_MEAN)
    # Loads grown from zero stay on the branch of the unloaded arm.
    assert result.converged.mean() >= 0.9
    np.testing.assert_allclose(result.force[result.converged], forces[result.converged],
                               atol=1e-6)


def test_solvers_broadcast_and_a_single_call_is_a_batch_of_one(arm):
    rng = np.random.default_rng(7)
    Q_m = random_motors(rng, 6).reshape(2, 3, 3)
    forces = rng.normal(size=(2, 3, 3)) * 15.0
    batch = spring_deflections(arm, Q_m, forces, [170.0, 175.0, 160.0, 180.0])
    assert batch.q_k.shape == (2, 3, 4) and batch.status.shape == (2, 3)
    tau = motor_torques(arm, np.array([[full_q(m, k) for m, k in zip(a, b, strict=True)]
                                       for a, b in zip(Q_m, batch.q_k, strict=True)]), forces)
    inverse = solve_load_newton(arm, Q_m, tau, [170.0, 175.0, 160.0, 180.0])
    for idx in np.ndindex(2, 3):
        one = spring_deflections(arm, Q_m[idx], forces[idx], [170.0, 175.0, 160.0, 180.0])
        assert isinstance(one.status, str) and isinstance(one.iterations, int)
        assert one.status == batch.status[idx] and one.iterations == batch.iterations[idx]
        np.testing.assert_array_equal(one.q_k, batch.q_k[idx])
        back = solve_load_newton(arm, Q_m[idx], tau[idx], [170.0, 175.0, 160.0, 180.0])
        np.testing.assert_array_equal(back.force, inverse.force[idx])
        np.testing.assert_allclose(back.force, forces[idx], atol=1e-8)


def test_solution_is_frozen_and_its_statuses_are_documented(arm):
    result = spring_deflections(arm, np.zeros(3), np.zeros(3), K_MEAN)
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.status = 'converged'
    assert result.status in STATUS_NAMES
    # U_m singular at the start (stretched straight up along the first joint axis): the force
    # of eq. (6) is not finite there, reported as diverged, not raised.
    singular = solve_load_newton(arm, [0.3, np.pi / 2, 0.0], [1.0, 2.0, 3.0], K_MEAN)
    assert singular.status == 'diverged' and singular.iterations == 0
    assert np.isnan(singular.force).all()


def test_stiffness_forms():
    np.testing.assert_array_equal(check_stiffness(172.71), [172.71] * 4)
    np.testing.assert_array_equal(check_stiffness(170), [170.0] * 4)
    np.testing.assert_array_equal(check_stiffness(np.array([1.0, 2.0, 3.0, 4.0])),
                                  [1.0, 2.0, 3.0, 4.0])


@pytest.mark.parametrize('stiffness, match', [
    (0.0, 'positive'), (-5.0, 'positive'), (np.nan, 'positive'), ([1.0, 2.0, 3.0], 'shape'),
    ([1.0, 2.0, -3.0, 4.0], 'positive'), ('stiff', 'stiffness'),
])
def test_bad_stiffness_raises(arm, stiffness, match):
    with pytest.raises(ValueError, match=match):
        spring_deflections(arm, np.zeros(3), np.zeros(3), stiffness)


@pytest.mark.parametrize('kwargs, match', [
    ({'q_m': [0.0, np.nan, 0.0]}, 'q_m'),
    ({'q_m': np.zeros(4)}, r'q_m of shape \(\.\.\., 3\)'),
    ({'force': [1.0, 2.0]}, r'force of shape \(\.\.\., 3\)'),
    ({'force': [1.0, np.inf, 0.0]}, 'force'),
    ({'force': np.zeros((2, 3)), 'q_m': np.zeros((3, 3))}, 'broadcast'),
    ({'q_k0': np.zeros(3)}, r'q_k0 of shape \(\.\.\., 4\)'),
    ({'tol': 0.0}, 'tol'),
    ({'max_iterations': 0}, 'max_iterations'),
    ({'max_iterations': 2.5}, 'max_iterations'),
])
def test_bad_input_raises(arm, kwargs, match):
    args = dict(q_m=np.zeros(3), force=np.zeros(3), stiffness=K_MEAN)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        spring_deflections(arm, **args)


def test_inverse_solvers_reject_bad_input(arm):
    with pytest.raises(ValueError, match='tau_m'):
        solve_load_newton(arm, np.zeros(3), [1.0, np.nan, 0.0], K_MEAN)
    with pytest.raises(ValueError, match='steps'):
        solve_load_continuation(arm, np.zeros(3), np.zeros(3), K_MEAN, steps=0)
    with pytest.raises(ValueError, match=r'q of shape \(\.\.\., 7\)'):
        motor_torques(arm, np.zeros(6), np.zeros(3))


def test_rigid_arm_is_refused():
    with pytest.raises(ValueError, match='FlexibleArm'):
        spring_deflections(RigidArm(), np.zeros(3), np.zeros(3), K_MEAN)


def test_no_private_name_crosses_a_package():
    # The finding of the review: the estimator and the IK imported the model's private hot
    # path (_stable, _solve_springs, ...). Every name one package takes from another is public.
    import ast
    from pathlib import Path

    root = Path(__file__).parents[2]
    offenders = []
    for path in root.glob('inflarm_*/inflarm_*/**/*.py'):
        package = path.relative_to(root).parts[0]
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(
                    'inflarm_') and node.module.split('.')[0] != package:
                offenders += [f'{path.relative_to(root)}: {node.module}.{alias.name}'
                              for alias in node.names if alias.name.startswith('_')]
    assert offenders == []
