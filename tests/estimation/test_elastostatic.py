"""Tests of inflarm_estimation.elastostatic: load and pose from motor torques (Fig. 5).

Ground truth comes from an independent forward solve: ``scipy.optimize.root`` on the spring
equilibrium k q_k = U_k^T f with the textbook DH Jacobian (``dh_jacobian_reference``, no
Pinocchio), and tau_m = U_m^T f from the same Jacobian.
"""

import numpy as np
import pytest

from elastostatic_reference import K_MEAN, M, full_q, reference_deflections
from inflarm_estimation.elastostatic import (
    estimate_load_and_pose,
    estimate_load_and_pose_batch,
    link_margins,
    link_moments,
)
from inflarm_model.elastostatics import spring_deflections
from inflarm_model.kinematics import FlexibleArm, dh_fk_reference, dh_jacobian_reference
from inflarm_model.link import LINK_RADIUS, wrinkling_moment


@pytest.fixture(scope='module')
def arm():
    return FlexibleArm()





def forward(arm, q_m, force, k):
    """Independent truth: spring deflections and motor torques under a tip force."""
    q_k = reference_deflections(arm, q_m, force, k, max_residual=1e-10)
    U = dh_jacobian_reference(arm.dh_table, full_q(q_m, q_k))[:3]
    return q_k, U[:, M].T @ force


def identifiable(arm, q_m, force, k, q_k):
    """Whether the truth lies on the sheet of tau_m(f) connected to f = 0, well conditioned.

    d tau_m / d f by central differences of the independent forward solve; its determinant
    must keep the sign it has at f = 0 (det U_m at q_k = 0), else at least two other loads
    give the same torques (degree argument).
    """
    h = 1e-4
    sens = np.empty((3, 3))
    for i in range(3):
        df = np.zeros(3)
        df[i] = h
        sens[:, i] = (forward(arm, q_m, force + df, k)[1] - forward(arm, q_m, force - df, k)[1])
    sens /= 2.0 * h
    U0 = dh_jacobian_reference(arm.dh_table, full_q(q_m, np.zeros(4)))[:3]
    same_sheet = np.sign(np.linalg.det(sens)) == np.sign(np.linalg.det(U0[:, M]))
    return same_sheet and np.linalg.cond(sens) < 1e3


def random_load(rng, f_max):
    d = rng.normal(size=3)
    return d / np.linalg.norm(d) * rng.uniform(0.0, f_max)


def random_motors(rng):
    # Elbow within +-2.6 rad: clear of the fully folded arm.
    return rng.uniform([-np.pi, -np.pi / 2, -2.6], [np.pi, np.pi / 2, 2.6])


def test_estimate_recovers_the_independent_equilibrium_up_to_100_n(arm):
    rng = np.random.default_rng(7)
    recovered = refused = 0
    for _ in range(60):
        q_m, force = random_motors(rng), random_load(rng, 100.0)
        q_k, tau_m = forward(arm, q_m, force, K_MEAN)
        estimate = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
        if estimate.converged:
            # Whatever it returns fits the torques (independent forward solve of its load).
            q_k_back, tau_back = forward(arm, q_m, estimate.force, K_MEAN)
            np.testing.assert_allclose(tau_back, tau_m, atol=1e-7)
            np.testing.assert_allclose(estimate.q_k, q_k_back, atol=1e-9)
        else:  # failures are reported, never numbers
            assert estimate.status in ('ambiguous', 'line_search', 'max_iterations', 'diverged')
            assert estimate.reason and np.isnan(estimate.force).all()
        if not identifiable(arm, q_m, force, K_MEAN, q_k):
            continue  # beyond a fold several loads fit the torques
        if estimate.status == 'ambiguous':
            refused += 1  # the solve met a folded solution: non-uniqueness proven, refused
            continue
        recovered += 1
        assert estimate.converged, estimate.reason
        np.testing.assert_allclose(estimate.force, force, atol=1e-6, rtol=0)
        np.testing.assert_allclose(estimate.q_k, q_k, atol=1e-9, rtol=0)
        np.testing.assert_allclose(estimate.tau_k, K_MEAN * q_k, atol=1e-6, rtol=0)
        np.testing.assert_allclose(
            estimate.tip_position, dh_fk_reference(arm.dh_table, full_q(q_m, q_k))[:3, 3],
            atol=1e-9)
    assert recovered >= 54 and refused <= 2, (recovered, refused)


def test_estimate_recovers_every_load_up_to_20_n(arm):
    rng = np.random.default_rng(7)
    for _ in range(25):
        q_m, force = random_motors(rng), random_load(rng, 20.0)
        q_k, tau_m = forward(arm, q_m, force, K_MEAN)
        estimate = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
        assert estimate.converged, estimate.reason
        np.testing.assert_allclose(estimate.force, force, atol=1e-6, rtol=0)
        np.testing.assert_allclose(estimate.q_k, q_k, atol=1e-9, rtol=0)


def test_paper_load_small_deflection_case(arm):
    q_m = np.array([0.3, 0.9, -1.4])
    force = np.array([0.0, 10.0, -15.0])  # f_e of section 4
    q_k, tau_m = forward(arm, q_m, force, K_MEAN)
    estimate = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
    assert estimate.converged and estimate.status == 'converged' and estimate.reason == ''
    assert estimate.iterations <= 6
    assert estimate.residual <= 1e-10
    np.testing.assert_allclose(estimate.force, force, atol=1e-9)
    np.testing.assert_allclose(estimate.q_k, q_k, atol=1e-11)


def test_fixed_point_diverges_where_newton_converges(arm):
    rng = np.random.default_rng(7)
    for _ in range(200):
        q_m, force = random_motors(rng), random_load(rng, 80.0)
        if np.linalg.norm(force) < 50.0:
            continue
        q_k, tau_m = spring_deflections(arm, q_m, force, K_MEAN).q_k, None
        q_k, tau_m = forward(arm, q_m, force, K_MEAN)
        paper = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN, method='fixed_point')
        if paper.converged:
            continue
        newton = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
        if not newton.converged:  # e.g. an ambiguous case; look for a clean one
            continue
        assert paper.status in ('diverged', 'max_iterations')
        assert np.isnan(paper.force).all()
        np.testing.assert_allclose(newton.force, force, atol=1e-6)
        np.testing.assert_allclose(newton.q_k, q_k, atol=1e-9)
        return
    pytest.fail('no load of 50-80 N found where the fixed point of Fig. 5 fails')


def test_fixed_point_agrees_with_newton_when_it_converges(arm):
    q_m = np.array([-0.4, 0.5, 1.1])
    force = np.array([3.0, -2.0, 4.0])
    _, tau_m = forward(arm, q_m, force, K_MEAN)
    paper = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN, method='fixed_point')
    newton = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
    assert paper.converged and newton.converged
    assert newton.iterations < paper.iterations
    np.testing.assert_allclose(paper.force, newton.force, atol=1e-8)
    np.testing.assert_allclose(paper.q_k, newton.q_k, atol=1e-11)


def test_per_spring_stiffness(arm):
    q_m = np.array([0.7, 0.4, -0.8])
    force = np.array([5.0, 10.0, -15.0])
    k = np.array([150.0, 190.0, 160.0, 185.0])
    q_k, tau_m = forward(arm, q_m, force, k)
    estimate = estimate_load_and_pose(arm, q_m, tau_m, k)
    assert estimate.converged
    np.testing.assert_allclose(estimate.force, force, atol=1e-8)
    np.testing.assert_allclose(estimate.q_k, q_k, atol=1e-11)
    np.testing.assert_allclose(estimate.tau_k, k * q_k, atol=1e-8)
    # The shared-stiffness model misreads the same torques.
    assert np.abs(estimate_load_and_pose(arm, q_m, tau_m, K_MEAN).q_k - q_k).max() > 1e-3


@pytest.mark.parametrize('q_m', [
    [0.3, np.pi / 2, 0.0],  # stretched up along the first joint axis: joint 1 cannot move it
    [0.0, 0.0, 0.0],  # stretched out: joints 2 and 5 move the tip the same way
], ids=['along-axis-1', 'stretched'])
def test_singular_motor_jacobian_is_reported(arm, q_m):
    estimate = estimate_load_and_pose(arm, q_m, [1.0, 2.0, 3.0], K_MEAN)
    assert not estimate.converged
    assert estimate.status == 'singular'
    assert 'near-singular' in estimate.reason
    assert estimate.condition_number > 1e6
    for field in (estimate.force, estimate.q_k, estimate.tau_k, estimate.tip_position):
        assert np.isnan(field).all()


def test_condition_number_is_the_2_norm_one_and_limits_the_estimate(arm):
    q_m = np.array([0.2, 0.6, -1.0])
    force = np.array([0.0, 10.0, -15.0])
    q_k, tau_m = forward(arm, q_m, force, K_MEAN)
    estimate = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
    U = dh_jacobian_reference(arm.dh_table, full_q(q_m, estimate.q_k))[:3]
    assert estimate.condition_number == pytest.approx(np.linalg.cond(U[:, M]), rel=1e-6)
    refused = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN,
                                     max_condition=0.5 * estimate.condition_number)
    assert refused.status == 'singular' and np.isnan(refused.force).all()


def test_ambiguous_solution_is_refused(arm):
    # Large loads near the folded elbow: find a case whose solution lies beyond a fold.
    rng = np.random.default_rng(7)
    for _ in range(3000):
        q_m, force = random_motors(rng), random_load(rng, 100.0)
        eq = spring_deflections(arm, q_m, force, K_MEAN)
        if not eq.converged:
            continue
        U = arm.jacobian(full_q(q_m, eq.q_k))[:3]
        estimate = estimate_load_and_pose(arm, q_m, U[:, M].T @ force, K_MEAN)
        if estimate.status == 'ambiguous':
            assert not estimate.converged
            assert np.isnan(estimate.force).all()
            assert 'fold' in estimate.reason and 'f = [' in estimate.reason
            return
    pytest.fail('no ambiguous case found')


def test_zero_torque_is_zero_load(arm):
    estimate = estimate_load_and_pose(arm, [0.1, 0.5, -1.0], np.zeros(3), K_MEAN)
    assert estimate.converged and estimate.iterations == 0
    np.testing.assert_array_equal(estimate.force, 0.0)
    np.testing.assert_array_equal(estimate.q_k, 0.0)


def test_batch_equals_single(arm):
    rng = np.random.default_rng(7)
    n = 120
    Q_m = np.array([random_motors(rng) for _ in range(n)])
    Q_m[:3] = [[0.3, np.pi / 2, 0.0], [0.0, 0.0, 0.0], [0.1, 0.2, 0.3]]  # singular cases
    forces = np.array([random_load(rng, 60.0) for _ in range(n)])
    Tau = np.empty((n, 3))
    for i in range(n):
        eq = spring_deflections(arm, Q_m[i], forces[i], K_MEAN)
        U = arm.jacobian(full_q(Q_m[i], eq.q_k))[:3]
        Tau[i] = U[:, M].T @ forces[i]
    batch = estimate_load_and_pose_batch(arm, Q_m, Tau, K_MEAN)
    assert batch.force.shape == (n, 3) and batch.q_k.shape == (n, 4)
    for i in range(n):
        one = estimate_load_and_pose(arm, Q_m[i], Tau[i], K_MEAN)
        assert batch.status[i] == one.status, i
        assert batch.converged[i] == one.converged
        np.testing.assert_allclose(batch.force[i], one.force, atol=1e-7)
        np.testing.assert_allclose(batch.q_k[i], one.q_k, atol=1e-10)
        np.testing.assert_allclose(batch.tip_position[i], one.tip_position, atol=1e-10)
        if one.converged:  # evaluated up to one final correction (<= 1e-6 rad) apart
            assert batch.condition_number[i] == pytest.approx(one.condition_number, rel=1e-3)
    assert batch.status[:2].tolist() == ['singular', 'singular']
    assert batch.converged.sum() >= n - 5


def test_link_margins_against_wrinkling(arm):
    q_m = np.array([0.2, 0.3, -0.6])
    force = np.array([0.0, 10.0, -15.0])
    q_k, tau_m = forward(arm, q_m, force, K_MEAN)
    estimate = estimate_load_and_pose(arm, q_m, tau_m, K_MEAN)
    moments = link_moments(arm, full_q(q_m, estimate.q_k), estimate.force)
    np.testing.assert_allclose(
        moments, np.hypot(estimate.tau_k[[0, 2]], estimate.tau_k[[1, 3]]), atol=1e-8)
    margins = link_margins(moments, 50e3, LINK_RADIUS)
    np.testing.assert_allclose(margins, wrinkling_moment(50e3, LINK_RADIUS) - moments)
    assert margins[0] < wrinkling_moment(50e3, LINK_RADIUS)
    per_link = link_margins(np.array([[10.0, 5.0], [30.0, 1.0]]), [20e3, 60e3], LINK_RADIUS)
    np.testing.assert_allclose(per_link, [[8.21 - 10.0, 24.63 - 5.0], [8.21 - 30.0, 23.63]],
                               atol=0.01)
    assert per_link[1, 0] < 0.0  # link 1 wrinkles at 20 kPa under 30 N·m


@pytest.mark.parametrize('args, match', [
    (dict(q_m=[0.0, np.nan, 0.0]), 'q_m'),
    (dict(q_m=[0.0, 0.0]), r'q_m of shape \(3,\)'),
    (dict(tau_m=np.zeros((3, 1))), r'tau_m of shape \(3,\)'),
    (dict(tau_m=[np.inf, 0.0, 0.0]), 'tau_m'),
    (dict(stiffness=0.0), 'stiffness'),
    (dict(stiffness=[170.0, 170.0, -1.0, 170.0]), 'stiffness'),
    (dict(stiffness=[170.0, 170.0]), 'stiffness'),
    (dict(method='gauss'), 'method'),
    (dict(tol=-1.0), 'tol'),
    (dict(max_iterations=0), 'max_iterations'),
    (dict(max_condition=0.5), 'max_condition'),
])
def test_bad_input_raises(arm, args, match):
    call = dict(q_m=[0.1, 0.5, -1.0], tau_m=[1.0, 2.0, 3.0], stiffness=K_MEAN)
    call.update(args)
    with pytest.raises(ValueError, match=match):
        estimate_load_and_pose(arm, **call)


def test_batch_bad_input_raises(arm):
    with pytest.raises(ValueError, match=r'Q_m of shape \(N, 3\)'):
        estimate_load_and_pose_batch(arm, np.zeros(3), np.zeros((1, 3)), K_MEAN)
    with pytest.raises(ValueError, match='Tau_m'):
        estimate_load_and_pose_batch(arm, np.zeros((2, 3)), np.zeros((3, 3)), K_MEAN)
    with pytest.raises(ValueError, match='Tau_m'):
        estimate_load_and_pose_batch(arm, np.zeros((2, 3)), np.full((2, 3), np.nan), K_MEAN)
    with pytest.raises(ValueError, match='moments'):
        link_margins(np.array([1.0, 2.0, 3.0]), 50e3, LINK_RADIUS)
    with pytest.raises(ValueError, match='moments'):
        link_margins(np.array([-1.0, 2.0]), 50e3, LINK_RADIUS)
    with pytest.raises(ValueError, match='pressure'):
        link_margins(np.array([1.0, 2.0]), -50e3, LINK_RADIUS)
