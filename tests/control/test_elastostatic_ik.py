"""Tests of inflarm_control.elastostatic_ik: elastostatic IK (section 2.4, eqs 8-9, Figs 10-11).

Deflected tips are checked with an independent forward solve: ``scipy.optimize.root`` on the
spring equilibrium with the textbook DH chain of ``inflarm_model.kinematics`` (no Pinocchio).
"""

import numpy as np
import pytest

from elastostatic_reference import K_MEAN, M, full_q, reference_deflections
from inflarm_control.elastostatic_ik import (
    effective_jacobian,
    minimum_pressure_along,
    motor_pseudo_inverse,
    solve_ik,
    solve_rigid_ik,
    straight_line_trajectory,
    track_trajectory,
)
from inflarm_control.ik_figures import X_GOAL, X_START, main, run_scenario
from inflarm_model.elastostatics import spring_deflections
from inflarm_model.kinematics import FlexibleArm, RigidArm, dh_fk_reference, dh_jacobian_reference
from inflarm_model.link import (
    LINK_RADIUS,
    TAU_MAX_LINK1,
    min_pressure_for_moment,
    wrinkling_moment,
)

F_PAPER = np.array([0.0, 10.0, -15.0])  # f_e of section 4 [N]


@pytest.fixture(scope='module')
def arm():
    return FlexibleArm()


@pytest.fixture(scope='module')
def rigid():
    return RigidArm()





def deflected_tip(arm, q_m, force, k):
    """Independent: equilibrium by scipy root on the textbook DH chain, then its FK."""
    q_k = reference_deflections(arm, q_m, force, k, max_residual=1e-10)
    return dh_fk_reference(arm.dh_table, full_q(q_m, q_k))[:3, 3]


TARGETS = [(0.7, 0.3, 0.4), (0.5, -0.6, 0.2), (0.9, 0.1, -0.3), (-0.4, 0.5, 0.6)]


def test_rigid_ik_inverts_table_1(rigid):
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, 3)
        x = dh_fk_reference(rigid.dh_table, q)[:3, 3]
        if np.linalg.norm(x) < 0.1 or np.hypot(x[0], x[1]) < 1e-3:
            continue
        np.testing.assert_allclose(solve_rigid_ik(rigid, x, q), q, atol=1e-9)
        # From a start on another branch it still lands on the target.
        other = solve_rigid_ik(rigid, x, q + np.array([np.pi, 0.0, 0.0]))
        np.testing.assert_allclose(dh_fk_reference(rigid.dh_table, other)[:3, 3], x, atol=1e-12)


@pytest.mark.parametrize('target', TARGETS)
def test_elastostatic_ik_puts_the_deflected_tip_on_target(arm, target):
    q_m = solve_ik(arm, target, F_PAPER, K_MEAN, np.array([0.0, 0.6, -1.2]))
    error = np.linalg.norm(deflected_tip(arm, q_m, F_PAPER, K_MEAN) - target)
    assert error <= 1e-7  # the paper's claim, to 0.1 mm, holds to 0.1 um


def test_rigid_ik_misses_by_the_deflection(arm, rigid):
    # Section 4's comparison: rigid IK angles on the deflecting arm miss the target by the
    # deflection, the elastostatic ones do not.
    misses = []
    for target in TARGETS:
        target = np.array(target)
        q0 = np.array([0.0, 0.6, -1.2])
        q_rigid = solve_rigid_ik(rigid, target, q0)
        q_flex = solve_ik(arm, target, F_PAPER, K_MEAN, q0)
        miss = np.linalg.norm(deflected_tip(arm, q_rigid, F_PAPER, K_MEAN) - target)
        hit = np.linalg.norm(deflected_tip(arm, q_flex, F_PAPER, K_MEAN) - target)
        deflection = np.linalg.norm(
            deflected_tip(arm, q_rigid, F_PAPER, K_MEAN)
            - dh_fk_reference(arm.dh_table, full_q(q_rigid, np.zeros(4)))[:3, 3])
        assert miss == pytest.approx(deflection, rel=1e-9)  # the whole miss is the deflection
        assert hit <= 1e-4 < 0.02 <= miss, f'rigid IK misses by {miss * 1e3:.1f} mm'
        misses.append(miss)
    assert min(misses) > 0.02, f'rigid-IK misses: {np.round(np.array(misses) * 1e3, 1)} mm'


def test_per_spring_stiffness(arm):
    target = np.array([0.6, 0.2, 0.5])
    k = np.array([150.0, 190.0, 160.0, 185.0])
    q_m = solve_ik(arm, target, F_PAPER, k, np.array([0.0, 0.6, -1.2]))
    assert np.linalg.norm(deflected_tip(arm, q_m, F_PAPER, k) - target) <= 1e-7
    mean_k = solve_ik(arm, target, F_PAPER, K_MEAN, np.array([0.0, 0.6, -1.2]))
    assert np.abs(q_m - mean_k).max() > 1e-4


@pytest.mark.parametrize('target, match', [
    ((1.3, 0.0, 0.0), 'beyond the reach'),
    ((0.0, 0.0, 1.2 + 1e-6), 'beyond the reach'),
    ((0.03, 0.02, 0.05), 'too close to the base'),
    ((0.0, 0.0, 0.8), 'first joint axis'),
    ((1.1999, 0.0, 0.0), 'singular'),  # within 2L, but only a stretched arm gets there
])
def test_unreachable_or_singular_targets_raise(arm, target, match):
    with pytest.raises(ValueError, match=match):
        solve_ik(arm, target, F_PAPER, K_MEAN, np.array([0.0, 0.3, -0.3]))


def test_rigid_ik_refuses_unreachable_targets(rigid):
    with pytest.raises(ValueError, match='beyond the reach'):
        solve_rigid_ik(rigid, [1.0, 1.0, 0.0], np.zeros(3))


def test_effective_jacobian_is_the_derivative_of_the_deflected_tip(arm):
    q_m = np.array([0.3, 0.7, -1.1])
    eq = spring_deflections(arm, q_m, F_PAPER, K_MEAN)
    J_eff = effective_jacobian(arm, full_q(q_m, eq.q_k), F_PAPER, K_MEAN)
    h = 1e-6
    numeric = np.empty((3, 3))
    for i in range(3):
        dq = np.zeros(3)
        dq[i] = h
        numeric[:, i] = (deflected_tip(arm, q_m + dq, F_PAPER, K_MEAN)
                         - deflected_tip(arm, q_m - dq, F_PAPER, K_MEAN)) / (2.0 * h)
    np.testing.assert_allclose(J_eff, numeric, atol=1e-7)


def test_motor_pseudo_inverse_is_the_motor_rows_of_eq_8(arm):
    q = np.random.default_rng(7).uniform(-1.0, 1.0, 7)
    U = dh_jacobian_reference(arm.dh_table, q)[:3]
    np.testing.assert_allclose(motor_pseudo_inverse(arm, q), np.linalg.pinv(U)[M], atol=1e-12)


def test_tracking_a_straight_line(arm):
    times, x_d, v_d = straight_line_trajectory(X_START, X_GOAL, 4.0, 200)
    np.testing.assert_allclose(x_d[[0, -1]], [X_START, X_GOAL])
    np.testing.assert_allclose(v_d[[0, -1]], 0.0, atol=1e-15)
    q0 = solve_ik(arm, x_d[0], F_PAPER, K_MEAN, np.array([0.0, 0.6, -1.2]))
    paper = track_trajectory(arm, times, x_d, v_d, F_PAPER, K_MEAN, q0, 40.0)
    exact = track_trajectory(arm, times, x_d, v_d, F_PAPER, K_MEAN, q0, 40.0,
                             method='effective')
    for result in (paper, exact):
        assert result.q_m.shape == (200, 3) and result.q.shape == (200, 7)
        np.testing.assert_allclose(result.q[:, M], result.q_m)
        assert result.tip_error[0] < 1e-9
        final = deflected_tip(arm, result.q_m[-1], F_PAPER, K_MEAN)
        np.testing.assert_allclose(result.tip_position[-1], final, atol=1e-9)
    # eq. (9) with the motor rows of the pseudo-inverse lags (springs are not free joints);
    # the effective Jacobian feeds v_d forward exactly.
    assert paper.tip_error.max() < 0.03 and paper.tip_error[-1] < 1e-3
    assert exact.tip_error.max() < 5e-4 and exact.tip_error[-1] < 1e-5  # Euler steps only
    assert exact.tip_error.max() < 0.1 * paper.tip_error.max()


def test_paper_scenario_pressure_requirement(arm):
    # Section 4: the largest moment, on link 1, needs p >= 50 kPa among 10-60 kPa (paper:
    # 17.51 N·m; our path of ik_figures gives the same order).
    scenario = run_scenario(samples=80)
    p = scenario.pressure
    assert p.link == 1
    assert wrinkling_moment(40e3, LINK_RADIUS) < p.max_moment < wrinkling_moment(50e3,
                                                                                 LINK_RADIUS)
    assert p.max_moment == pytest.approx(TAU_MAX_LINK1, abs=1.0)
    assert p.lowest_sufficient_pressure == 50e3
    assert p.required_pressure == pytest.approx(min_pressure_for_moment(p.max_moment,
                                                                        LINK_RADIUS))
    miss = np.linalg.norm(scenario.rigid_tip - scenario.x_d, axis=1)
    assert miss.min() > 0.05  # rigid IK on the loaded arm misses by centimetres
    again = minimum_pressure_along(arm, scenario.flexible.q_m, F_PAPER, K_MEAN, LINK_RADIUS)
    assert again.max_moment == pytest.approx(p.max_moment, rel=1e-9)


def test_ik_figures_cli_writes_both_figures(tmp_path, capsys):
    assert main(['--out', str(tmp_path), '--samples', '40']) == 0
    assert (tmp_path / 'fig10_configurations.png').stat().st_size > 10_000
    assert (tmp_path / 'fig11_motor_angles.png').stat().st_size > 10_000
    out = capsys.readouterr().out
    assert 'max link moment' in out and 'lowest tested pressure that holds it: 50 kPa' in out


@pytest.mark.parametrize('kwargs, match', [
    (dict(target=[0.5, np.nan, 0.2]), 'target'),
    (dict(target=[0.5, 0.2]), r'target of shape \(3,\)'),
    (dict(force=[0.0, 10.0]), r'force of shape \(3,\)'),
    (dict(stiffness=-1.0), 'stiffness'),
    (dict(q_m0=[0.0, 0.0]), r'q_m0 of shape \(3,\)'),
    (dict(tol=0.0), 'tol'),
])
def test_solve_ik_bad_input_raises(arm, kwargs, match):
    args = dict(target=[0.6, 0.2, 0.3], force=F_PAPER, stiffness=K_MEAN, q_m0=np.zeros(3))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        solve_ik(arm, **args)


def test_track_trajectory_bad_input_raises(arm):
    times, x_d, v_d = straight_line_trajectory(X_START, X_GOAL, 1.0, 5)
    q0 = np.zeros(3)
    with pytest.raises(ValueError, match='times'):
        track_trajectory(arm, times[::-1], x_d, v_d, F_PAPER, K_MEAN, q0, 10.0)
    with pytest.raises(ValueError, match='x_d'):
        track_trajectory(arm, times, x_d[:4], v_d, F_PAPER, K_MEAN, q0, 10.0)
    with pytest.raises(ValueError, match='gain'):
        track_trajectory(arm, times, x_d, v_d, F_PAPER, K_MEAN, q0, -1.0)
    with pytest.raises(ValueError, match='gain'):
        track_trajectory(arm, times, x_d, v_d, F_PAPER, K_MEAN, q0, np.ones((2, 2)))
    with pytest.raises(ValueError, match='method'):
        track_trajectory(arm, times, x_d, v_d, F_PAPER, K_MEAN, q0, 10.0, method='jacobi')
    with pytest.raises(ValueError, match='samples'):
        straight_line_trajectory(X_START, X_GOAL, 1.0, 1)
    with pytest.raises(ValueError, match='q_trajectory'):
        minimum_pressure_along(arm, np.zeros((3, 5)), F_PAPER, K_MEAN, LINK_RADIUS)
