"""Kinematics and work space of the pneumatic soft arm (inflarm_model.soft_arm), no ROS."""


import numpy as np
import pytest

from inflarm_model.soft_arm import (
    BELLOWS_PUSH,
    CHAMBERS,
    QUADRANT_BELLOWS,
    WORKSPACE_NEGATIVE,
    WORKSPACE_POSITIVE,
    central_axes,
    check_in_workspace,
    forward_kinematics,
    inverse_kinematics,
    pea_length_from_end_point,
    quadrant_of,
)


def _random_configurations(rng, n):
    l1 = rng.uniform(0.29, 0.49, n)
    phi = rng.uniform(-np.pi, np.pi, n)
    theta = rng.uniform(0.0, 0.6, n)
    return l1, phi, theta


def test_chamber_order_is_pea_then_bellows():
    assert CHAMBERS == ('PEA', 'B1', 'B2', 'B3', 'B4')


def test_forward_kinematics_satisfies_eq6():
    rng = np.random.default_rng(7)
    l1, phi, theta = _random_configurations(rng, 200)
    p = forward_kinematics(l1, phi, theta)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    np.testing.assert_allclose((z - l1) ** 2 + x ** 2 + y ** 2, l1 ** 2, rtol=1e-12)
    np.testing.assert_allclose(pea_length_from_end_point(p), l1, rtol=1e-12)


def test_inverse_of_forward_is_identity():
    rng = np.random.default_rng(7)
    l1, phi, theta = _random_configurations(rng, 200)
    theta[0] = 0.0  # straight arm: direction is undefined, only l1 and theta must match
    config = inverse_kinematics(forward_kinematics(l1, phi, theta))
    np.testing.assert_allclose(config.pea_length, l1, rtol=1e-12)
    np.testing.assert_allclose(config.bend_angle, theta, atol=1e-12)
    np.testing.assert_allclose(config.bend_direction[1:], phi[1:], atol=1e-9)


def test_forward_of_inverse_reaches_workspace_points():
    rng = np.random.default_rng(7)
    points = rng.uniform([-0.2, -0.2, 0.58], [0.2, 0.2, 0.99], (100, 3))
    c = inverse_kinematics(points)
    np.testing.assert_allclose(
        forward_kinematics(c.pea_length, c.bend_direction, c.bend_angle), points, atol=1e-12)


def test_single_point_returns_floats():
    c = inverse_kinematics([0.0, 0.0, 0.604])
    assert isinstance(c.pea_length, float)
    assert c.pea_length == pytest.approx(0.302)
    assert c.bend_angle == pytest.approx(0.0)


def test_central_axes_join_mount_joint_and_end():
    end = np.array([0.100, 0.110, 0.670])
    axes = central_axes(end)
    assert axes.shape == (2, 2, 3)
    l1 = pea_length_from_end_point(end)
    np.testing.assert_allclose(axes[0, 0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(axes[0, 1], [0.0, 0.0, l1])
    np.testing.assert_allclose(axes[1, 0], axes[0, 1])
    np.testing.assert_allclose(axes[1, 1], end)
    # PEA1 and PEA2 have the same length (delta l1 = delta l2)
    np.testing.assert_allclose(np.linalg.norm(axes[:, 1] - axes[:, 0], axis=-1), [l1, l1])


def test_central_axes_are_batched():
    rng = np.random.default_rng(7)
    points = rng.uniform([-0.2, -0.2, 0.6], [0.2, 0.2, 0.9], (4, 5, 3))
    axes = central_axes(points)
    assert axes.shape == (4, 5, 2, 2, 3)
    np.testing.assert_allclose(axes[2, 3], central_axes(points[2, 3]))


def test_workspace_accepts_bounds_and_inside_points():
    check_in_workspace([0.202, -0.202, 0.574])
    check_in_workspace([[0.0, 0.0, 0.990], [0.1, 0.11, 0.67]])
    check_in_workspace([0.3, 0.0, 0.2], WORKSPACE_NEGATIVE)


@pytest.mark.parametrize(('point', 'message'), [
    ([0.0, 0.0, 1.1], 'target z = 1.100 m above the workspace maximum 0.990 m'),
    ([0.0, 0.0, 0.5], 'target z = 0.500 m below the workspace minimum 0.574 m'),
    ([0.25, 0.0, 0.7], 'target x = 0.250 m above the workspace maximum 0.202 m'),
    ([0.0, -0.3, 0.7], 'target y = -0.300 m below the workspace minimum -0.202 m'),
])
def test_workspace_names_the_violated_bound(point, message):
    with pytest.raises(ValueError, match=message):
        check_in_workspace(point)


def test_workspace_names_the_offending_point_of_a_batch():
    with pytest.raises(ValueError, match=r'goal\[1\] x = 0\.400 m above .* 0\.350 m'):
        check_in_workspace([[0.0, 0.0, 0.7], [0.4, 0.0, 0.7]], WORKSPACE_NEGATIVE, name='goal')


def test_workspace_bounds_are_the_papers():
    assert (WORKSPACE_POSITIVE.x_max, WORKSPACE_POSITIVE.z_min, WORKSPACE_POSITIVE.z_max) == (
        0.202, 0.574, 0.990)
    assert (WORKSPACE_NEGATIVE.y_max, WORKSPACE_NEGATIVE.z_min) == (0.350, 0.162)


def test_fig4_bellows_pairs_push_into_their_quadrant():
    signs = {1: (1, 1), 2: (-1, 1), 3: (-1, -1), 4: (1, -1)}
    for q, (bx, by) in QUADRANT_BELLOWS.items():
        push = np.add(BELLOWS_PUSH[bx], BELLOWS_PUSH[by])
        assert tuple(np.sign(push).astype(int)) == signs[q]
        assert quadrant_of(*push) == q
    # Fig 4 as the paper states it
    assert {frozenset(pair) for pair in QUADRANT_BELLOWS.values()} == {
        frozenset(p) for p in (('B3', 'B4'), ('B2', 'B3'), ('B1', 'B2'), ('B1', 'B4'))}


def test_section_3_1_q2_example_is_not_fig4_q2():
    # B4 drives x and B1 drives y in the text's Q2 example; those push into Q4
    push = np.add(BELLOWS_PUSH['B4'], BELLOWS_PUSH['B1'])
    assert quadrant_of(*push) == 4
    assert set(QUADRANT_BELLOWS[2]) == {'B2', 'B3'}


def test_quadrant_of_puts_axes_on_the_non_negative_side():
    np.testing.assert_array_equal(
        quadrant_of([0.0, -0.1, 0.0, 0.1], [0.0, 0.0, -0.1, -0.0]), [1, 2, 4, 1])


@pytest.mark.parametrize(('call', 'message'), [
    (lambda: pea_length_from_end_point([0.1, 0.2]), r'end_point of shape \(3,\)'),
    (lambda: pea_length_from_end_point([0.0, np.nan, 0.7]), 'finite end_point'),
    (lambda: pea_length_from_end_point([0.1, 0.0, 0.0]), 'z > 0'),
    (lambda: forward_kinematics(0.0, 0.0, 0.1), 'pea_length > 0'),
    (lambda: forward_kinematics(0.3, 0.0, np.pi), r'bend_angle in \[0, pi\)'),
    (lambda: forward_kinematics(0.3, np.inf, 0.1), 'finite bend_direction'),
    (lambda: check_in_workspace([np.nan, 0.0, 0.7]), 'finite target'),
    (lambda: quadrant_of(np.nan, 0.0), 'finite x and y'),
])
def test_bad_input_is_rejected(call, message):
    with pytest.raises(ValueError, match=message):
        call()
