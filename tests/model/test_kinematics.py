"""Tests of inflarm_model.kinematics and inflarm_model.urdf (sections 2.1-2.3, Tables 1-2,
eq. 4 of 000_ce37cf035a0a87c6).

Three implementations are cross-checked: Pinocchio on the generated URDF (single
configurations), the vectorized numpy recursion (batches) and the per-joint 4x4 reference.
"""

import math
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from inflarm_model.kinematics import (
    DHChain,
    FlexibleArm,
    RigidArm,
    dh_fk_reference,
    dh_frames_reference,
    dh_jacobian_reference,
    dh_transform,
)
from inflarm_model.urdf import (
    INFLARM_XMLNS,
    dh_chain_urdf,
    flexible_arm_urdf,
    flexible_dh_table,
    rigid_arm_urdf,
    spring_stiffness_from_urdf,
)

L = 0.6
L1 = 0.03
L2 = L - L1
TOL = 1e-12


@pytest.fixture(scope='module')
def rigid():
    return RigidArm(link_length=L)


@pytest.fixture(scope='module')
def flexible():
    return FlexibleArm(link_length=L, spring_offset=L1)


@pytest.fixture(scope='module', params=['rigid', 'flexible', 'generic'])
def arm(request):
    if request.param == 'rigid':
        return RigidArm(link_length=L)
    if request.param == 'flexible':
        return FlexibleArm(link_length=L, spring_offset=L1)
    # A chain with offsets d_i and arbitrary twists, which neither table of the paper has.
    rng = np.random.default_rng(7)
    table = np.column_stack([
        rng.uniform(0.0, 0.5, 5), rng.uniform(-np.pi, np.pi, 5), rng.uniform(-0.3, 0.3, 5),
    ])
    table[1] = [0.0, np.pi / 2, 0.2]
    return DHChain(table, [f'j{i}' for i in range(5)])


def random_q(rng, n, size=None):
    shape = (n,) if size is None else (size, n)
    return rng.uniform(-np.pi, np.pi, shape)


# --- three implementations agree -------------------------------------------------------------


def test_single_configuration_matches_reference(arm):
    rng = np.random.default_rng(7)
    for _ in range(25):
        q = random_q(rng, arm.n_joints)
        T_ref = dh_fk_reference(arm.dh_table, q)
        J_ref = dh_jacobian_reference(arm.dh_table, q)
        np.testing.assert_allclose(arm.fk(q), T_ref, rtol=0, atol=TOL)
        np.testing.assert_allclose(arm.jacobian(q), J_ref, rtol=0, atol=TOL)
        T, J = arm.fk_and_jacobian(q)
        np.testing.assert_allclose(T, T_ref, rtol=0, atol=TOL)
        np.testing.assert_allclose(J, J_ref, rtol=0, atol=TOL)


def test_batch_matches_reference(arm):
    rng = np.random.default_rng(7)
    Q = random_q(rng, arm.n_joints, size=1100)  # spans several internal chunks
    T_ref = np.array([dh_fk_reference(arm.dh_table, q) for q in Q])
    J_ref = np.array([dh_jacobian_reference(arm.dh_table, q) for q in Q])
    np.testing.assert_allclose(arm.fk_batch(Q), T_ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(arm.jacobian_batch(Q), J_ref, rtol=0, atol=TOL)
    T, J = arm.fk_and_jacobian_batch(Q)
    assert T.shape == (1100, 4, 4)
    assert J.shape == (1100, 6, arm.n_joints)
    np.testing.assert_allclose(T, T_ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(J, J_ref, rtol=0, atol=TOL)


def test_batch_of_zero_and_one(arm):
    rng = np.random.default_rng(7)
    assert arm.fk_batch(np.empty((0, arm.n_joints))).shape == (0, 4, 4)
    assert arm.jacobian_batch(np.empty((0, arm.n_joints))).shape == (0, 6, arm.n_joints)
    q = random_q(rng, arm.n_joints)
    np.testing.assert_allclose(arm.fk_batch([q])[0], arm.fk(q), rtol=0, atol=TOL)


def test_joint_origins_match_reference_frames(arm):
    rng = np.random.default_rng(7)
    q = random_q(rng, arm.n_joints)
    origins = arm.joint_origins(q)
    assert origins.shape == (arm.n_joints + 1, 3)
    np.testing.assert_allclose(
        origins, dh_frames_reference(arm.dh_table, q)[:, :3, 3], rtol=0, atol=TOL
    )
    np.testing.assert_array_equal(origins[0], np.zeros(3))
    np.testing.assert_allclose(origins[-1], arm.fk(q)[:3, 3], rtol=0, atol=TOL)


def test_reference_jacobian_columns_follow_eq4():
    # Column i of eq. (4) from the frames directly, one joint at a time.
    rng = np.random.default_rng(7)
    table = flexible_dh_table(L, L1)
    q = random_q(rng, 7)
    frames = dh_frames_reference(table, q)
    J = dh_jacobian_reference(table, q)
    for i in range(7):
        z, p = frames[i][:3, 2], frames[i][:3, 3]
        np.testing.assert_allclose(J[:3, i], np.cross(z, frames[-1][:3, 3] - p), atol=TOL)
        np.testing.assert_allclose(J[3:, i], z, atol=TOL)


def test_dh_transform_is_rz_tz_tx_rx():
    rng = np.random.default_rng(7)
    a, alpha, d, theta = rng.uniform(-2, 2, 4)

    def rot(axis, angle):
        R = np.eye(4)
        c, s = math.cos(angle), math.sin(angle)
        i, j = {'x': (1, 2), 'z': (0, 1)}[axis]
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
        return R

    def trans(axis, dist):
        T = np.eye(4)
        T['xyz'.index(axis), 3] = dist
        return T

    expected = rot('z', theta) @ trans('z', d) @ trans('x', a) @ rot('x', alpha)
    np.testing.assert_allclose(dh_transform(a, alpha, d, theta), expected, atol=TOL)


# --- the Jacobian is the derivative of the forward kinematics --------------------------------


def skew_to_vector(S):
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2


def test_jacobian_matches_finite_differences(arm):
    rng = np.random.default_rng(7)
    h = 1e-6
    for _ in range(5):
        q = random_q(rng, arm.n_joints)
        J = arm.jacobian(q)
        R = arm.fk(q)[:3, :3]
        for i in range(arm.n_joints):
            dq = np.zeros(arm.n_joints)
            dq[i] = h
            T_plus, T_minus = arm.fk(q + dq), arm.fk(q - dq)
            # Linear rows: central difference of the tip position [m/rad].
            np.testing.assert_allclose(
                J[:3, i], (T_plus[:3, 3] - T_minus[:3, 3]) / (2 * h), rtol=0, atol=1e-8
            )
            # Angular rows: dR R^T is the skew matrix of the angular velocity.
            omega = skew_to_vector((T_plus[:3, :3] - T_minus[:3, :3]) / (2 * h) @ R.T)
            np.testing.assert_allclose(J[3:, i], omega, rtol=0, atol=1e-8)


# --- the flexible arm reduces to the rigid one -----------------------------------------------


def test_flexible_with_relaxed_springs_is_rigid(rigid, flexible):
    rng = np.random.default_rng(7)
    for _ in range(20):
        q_m = rng.uniform(-np.pi, np.pi, 3)
        q = FlexibleArm.assemble_q(q_m, np.zeros(4))
        T_flex, J_flex = flexible.fk_and_jacobian(q)
        T_rigid, J_rigid = rigid.fk_and_jacobian(q_m)
        np.testing.assert_allclose(T_flex, T_rigid, rtol=0, atol=TOL)
        np.testing.assert_allclose(
            J_flex[:, list(FlexibleArm.MOTOR_INDICES)], J_rigid, rtol=0, atol=TOL
        )


def test_flexible_batch_with_relaxed_springs_is_rigid(rigid, flexible):
    rng = np.random.default_rng(7)
    Q_m = rng.uniform(-np.pi, np.pi, (600, 3))
    Q = np.zeros((600, 7))
    Q[:, list(FlexibleArm.MOTOR_INDICES)] = Q_m
    T_flex, J_flex = flexible.fk_and_jacobian_batch(Q)
    T_rigid, J_rigid = rigid.fk_and_jacobian_batch(Q_m)
    np.testing.assert_allclose(T_flex, T_rigid, rtol=0, atol=TOL)
    np.testing.assert_allclose(J_flex[:, :, [0, 1, 4]], J_rigid, rtol=0, atol=TOL)


# --- geometry worked out by hand -------------------------------------------------------------


@pytest.mark.parametrize(
    ('q', 'tip'),
    [
        ((0.0, 0.0, 0.0), (2 * L, 0.0, 0.0)),  # stretched along x0
        ((np.pi / 2, 0.0, 0.0), (0.0, 2 * L, 0.0)),  # base yaw about z0
        ((0.0, np.pi / 2, 0.0), (0.0, 0.0, 2 * L)),  # shoulder lifts the arm upright
        ((0.0, 0.0, np.pi / 2), (L, 0.0, L)),  # elbow bends the forearm up
    ],
)
def test_rigid_tip_by_hand(rigid, q, tip):
    np.testing.assert_allclose(rigid.fk(q)[:3, 3], tip, rtol=0, atol=TOL)


def test_first_spring_bends_link_about_vertical_axis(flexible):
    # spring_1 (DH joint 3) turns everything beyond l1 about the vertical through (l1, 0, 0).
    theta = 0.2
    q = FlexibleArm.assemble_q(np.zeros(3), [theta, 0.0, 0.0, 0.0])
    reach = L2 + L
    expected = (L1 + reach * math.cos(theta), reach * math.sin(theta), 0.0)
    np.testing.assert_allclose(flexible.fk(q)[:3, 3], expected, rtol=0, atol=TOL)


def test_second_spring_bends_link_in_vertical_plane(flexible):
    theta = 0.2
    q = FlexibleArm.assemble_q(np.zeros(3), [0.0, theta, 0.0, 0.0])
    reach = L2 + L
    expected = (L1 + reach * math.cos(theta), 0.0, reach * math.sin(theta))
    np.testing.assert_allclose(flexible.fk(q)[:3, 3], expected, rtol=0, atol=TOL)


def test_segment_lengths_do_not_depend_on_q(flexible):
    rng = np.random.default_rng(7)
    expected = [0.0, L1, 0.0, L2, L1, 0.0, L2]  # the a_i of Table 2
    for _ in range(5):
        origins = flexible.joint_origins(random_q(rng, 7))
        np.testing.assert_allclose(
            np.linalg.norm(np.diff(origins, axis=0), axis=1), expected, rtol=0, atol=TOL
        )


def test_pose_is_a_rigid_transform(flexible):
    rng = np.random.default_rng(7)
    T = flexible.fk_batch(random_q(rng, 7, size=50))
    R = T[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape),
                               atol=TOL)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=TOL)
    np.testing.assert_array_equal(T[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (50, 4)))


# --- calls do not share memory, inputs are coerced -------------------------------------------


def test_results_survive_later_calls(flexible):
    rng = np.random.default_rng(7)
    q1, q2 = random_q(rng, 7), random_q(rng, 7)
    T1, J1 = flexible.fk_and_jacobian(q1)
    T1_copy, J1_copy = T1.copy(), J1.copy()
    flexible.fk_and_jacobian(q2)
    flexible.fk(q2)
    np.testing.assert_array_equal(T1, T1_copy)
    np.testing.assert_array_equal(J1, J1_copy)


def test_accepts_lists_ints_and_strided_arrays(flexible):
    rng = np.random.default_rng(7)
    q = random_q(rng, 7)
    expected = dh_fk_reference(flexible.dh_table, q)
    np.testing.assert_allclose(flexible.fk(q.tolist()), expected, atol=TOL)
    strided = np.zeros(14)
    strided[::2] = q
    np.testing.assert_allclose(flexible.fk(strided[::2]), expected, atol=TOL)
    ints = [1, 0, 0, 0, 2, 0, 0]
    np.testing.assert_allclose(
        flexible.fk(ints), dh_fk_reference(flexible.dh_table, np.array(ints, float)), atol=TOL
    )


def test_huge_finite_angles_are_accepted(flexible):
    # |q| so large that the cheap finiteness test overflows: the exact check must accept it.
    q = np.full(7, 1.7e308)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        T = flexible.fk(q)
    np.testing.assert_allclose(T, dh_fk_reference(flexible.dh_table, q), atol=1e-9)


# --- motor / spring bookkeeping --------------------------------------------------------------


def test_joint_names_and_indices_agree():
    names = FlexibleArm.JOINT_NAMES
    assert names == (
        'joint_1', 'joint_2', 'spring_1', 'spring_2', 'joint_3', 'spring_3', 'spring_4',
    )
    assert FlexibleArm.MOTOR_INDICES == (0, 1, 4)
    assert FlexibleArm.SPRING_INDICES == (2, 3, 5, 6)
    assert tuple(names[i] for i in FlexibleArm.MOTOR_INDICES) == FlexibleArm.MOTOR_JOINT_NAMES
    assert tuple(names[i] for i in FlexibleArm.SPRING_INDICES) == FlexibleArm.SPRING_JOINT_NAMES
    assert FlexibleArm.MOTOR_JOINT_NAMES == ('joint_1', 'joint_2', 'joint_3')
    assert FlexibleArm.SPRING_JOINT_NAMES == ('spring_1', 'spring_2', 'spring_3', 'spring_4')
    assert RigidArm.JOINT_NAMES == ('joint_1', 'joint_2', 'joint_3')


def test_assemble_and_split_round_trip(flexible):
    rng = np.random.default_rng(7)
    q_m, q_k = rng.uniform(-1, 1, 3), rng.uniform(-0.1, 0.1, 4)
    q = flexible.assemble_q(q_m, q_k)
    assert q.shape == (7,)
    np.testing.assert_array_equal(q[[0, 1, 4]], q_m)  # theta_1, theta_2, theta_5
    np.testing.assert_array_equal(q[[2, 3, 5, 6]], q_k)  # theta_3, theta_4, theta_6, theta_7
    back_m, back_k = flexible.split_q(q)
    np.testing.assert_array_equal(back_m, q_m)
    np.testing.assert_array_equal(back_k, q_k)


def test_pinocchio_model_is_in_dh_order(arm):
    assert list(arm.model.names)[1:] == list(arm.joint_names)
    assert arm.model.nq == arm.model.nv == arm.n_joints
    assert arm.model.frames[arm.tip_frame_id].name == 'tip'


def test_lengths_are_exposed(rigid, flexible):
    assert rigid.link_length == L
    assert (flexible.link_length, flexible.spring_offset) == (L, L1)
    assert FlexibleArm(1.0, 0.25).dh_table[3, 0] == 0.75  # l2 = L - l1


def test_dh_table_is_table_2_and_read_only(flexible):
    h = np.pi / 2
    expected = [
        [0, h, 0], [L1, -h, 0], [0, h, 0], [L2, 0, 0], [L1, -h, 0], [0, h, 0], [L2, 0, 0],
    ]
    np.testing.assert_allclose(flexible.dh_table, expected, atol=TOL)
    with pytest.raises(ValueError, match='read-only'):
        flexible.dh_table[0, 0] = 1.0


# --- URDF ------------------------------------------------------------------------------------


def test_flexible_urdf_builds_the_same_kinematics(flexible):
    text = flexible_arm_urdf(L, L1, radius=0.08, stiffness=150.0)
    model = pin.buildModelFromXML(text)
    data = model.createData()
    tip = model.getFrameId('tip', pin.BODY)
    assert list(model.names)[1:] == list(FlexibleArm.JOINT_NAMES)
    assert all(j.shortname() == 'JointModelRZ' for j in list(model.joints)[1:])
    rng = np.random.default_rng(7)
    q = random_q(rng, 7)
    J = pin.computeFrameJacobian(model, data, q, tip, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(data.oMf[tip].homogeneous, flexible.fk(q), atol=TOL)
    np.testing.assert_allclose(J, flexible.jacobian(q), atol=TOL)


def test_urdf_structure_and_visuals():
    root = ET.fromstring(flexible_arm_urdf(L, L1, radius=0.07))
    links = [link.get('name') for link in root.iter('link')]
    assert links[0] == 'base_link' and links[-1] == 'tip'
    joints = {j.get('name'): j.get('type') for j in root.iter('joint')}
    assert joints == {**dict.fromkeys(FlexibleArm.JOINT_NAMES, 'revolute'), 'tip_joint': 'fixed'}
    cylinders = [v.find('geometry/cylinder') for v in root.iter('visual')]
    assert {c.get('radius') for c in cylinders} == {'0.07'}
    # The visuals cover both inflatable links end to end, and so do the collisions.
    np.testing.assert_allclose(sum(float(c.get('length')) for c in cylinders), 2 * L)
    collisions = [c.find('geometry/cylinder') for c in root.iter('collision')]
    assert [c.attrib for c in collisions] == [c.attrib for c in cylinders]


def test_spring_stiffness_round_trip():
    text = flexible_arm_urdf(L, L1, stiffness=172.71)
    springs = FlexibleArm.SPRING_JOINT_NAMES
    assert spring_stiffness_from_urdf(text) == dict.fromkeys(springs, 172.71)
    per_spring = [150.0, 160.5, 170.25, 180.125]
    text = flexible_arm_urdf(L, L1, stiffness=per_spring)
    assert spring_stiffness_from_urdf(text) == dict(
        zip(springs, per_spring, strict=True)
    )
    assert spring_stiffness_from_urdf(rigid_arm_urdf(L)) == {}
    assert f'xmlns:inflarm="{INFLARM_XMLNS}"' in text


def test_stiffness_of_unknown_joint_is_rejected():
    with pytest.raises(ValueError, match=r"expected spring_stiffness keys .* got 'c'"):
        dh_chain_urdf('arm', np.zeros((2, 3)), ['a', 'b'], spring_stiffness={'c': 1.0})


def test_rigid_urdf_builds_the_rigid_arm(rigid):
    model = pin.buildModelFromXML(rigid_arm_urdf(L))
    data = model.createData()
    q = np.array([0.3, -0.7, 1.1])
    pin.framesForwardKinematics(model, data, q)
    tip = model.getFrameId('tip', pin.BODY)
    np.testing.assert_allclose(data.oMf[tip].homogeneous, rigid.fk(q), atol=TOL)


@pytest.mark.parametrize(
    ('text', 'match'),
    [
        ('<robot', 'text'),
        (
            f'<robot xmlns:inflarm="{INFLARM_XMLNS}"><joint name="spring_1"/>'
            '<inflarm:spring joint="spring_9" stiffness="1.0"/></robot>',
            'spring_9',
        ),
        (
            f'<robot xmlns:inflarm="{INFLARM_XMLNS}"><joint name="spring_1"/>'
            '<inflarm:spring joint="spring_1" stiffness="-3"/></robot>',
            'stiffness',
        ),
        (
            f'<robot xmlns:inflarm="{INFLARM_XMLNS}"><joint name="spring_1"/>'
            '<inflarm:spring joint="spring_1" stiffness="1"/>'
            '<inflarm:spring joint="spring_1" stiffness="2"/></robot>',
            'once',
        ),
        (
            f'<robot xmlns:inflarm="{INFLARM_XMLNS}"><joint name="spring_1"/>'
            '<inflarm:spring joint="spring_1"/></robot>',
            'stiffness',
        ),
    ],
)
def test_spring_stiffness_from_bad_urdf(text, match):
    with pytest.raises(ValueError, match=match):
        spring_stiffness_from_urdf(text)


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'stiffness': -1.0}, r'expected stiffness to be positive and finite'),
        ({'stiffness': [1.0, 2.0]}, r'expected stiffness of shape'),
        ({'stiffness': [1.0, 2.0, 0.0, 1.0]}, r'expected stiffness to be positive'),
        ({'stiffness': np.nan}, r'expected stiffness to be positive and finite'),
        ({'stiffness': 'stiff'}, r'expected stiffness as a float'),
        ({'radius': 0.0}, r'expected radius'),
        ({'spring_offset': 0.6}, r'spring_offset'),
    ],
)
def test_flexible_urdf_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        flexible_arm_urdf(**kwargs)


# --- bad input -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'spring_offset': 0.6}, r'expected spring_offset < link_length'),
        ({'spring_offset': 0.7}, r'expected spring_offset < link_length'),
        ({'spring_offset': 0.0}, r'expected spring_offset to be a positive finite length'),
        ({'spring_offset': -0.03}, r'expected spring_offset to be a positive finite length'),
        ({'spring_offset': np.nan}, r'expected spring_offset'),
        ({'spring_offset': 'a'}, r'expected spring_offset'),
        ({'link_length': 0.0}, r'expected link_length to be a positive finite length'),
        ({'link_length': np.inf}, r'expected link_length'),
        ({'link_length': None}, r'expected link_length'),
    ],
)
def test_flexible_arm_rejects_bad_lengths(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FlexibleArm(**kwargs)


@pytest.mark.parametrize('link_length', [0.0, -1.0, np.nan, np.inf])
def test_rigid_arm_rejects_bad_length(link_length):
    with pytest.raises(ValueError, match='expected link_length'):
        RigidArm(link_length)


@pytest.mark.parametrize('method', ['fk', 'jacobian', 'fk_and_jacobian', 'joint_origins'])
@pytest.mark.parametrize(
    ('q', 'match'),
    [
        (np.zeros(6), r'expected q of shape \(7,\), got \(6,\)'),
        (np.zeros((7, 1)), r'expected q of shape \(7,\), got \(7, 1\)'),
        (np.zeros((1, 7)), r'expected q of shape \(7,\), got \(1, 7\)'),
        (0.0, r'expected q of shape \(7,\), got \(\)'),
        ([0, 0, 0, np.nan, 0, 0, 0], r'expected q to be finite'),
        ([0, 0, 0, 0, 0, 0, np.inf], r'expected q to be finite'),
        ([0, 0, 0, np.inf, 0, 0, -np.inf], r'expected q to be finite'),
        (['a'] * 7, r'expected q of shape \(7,\)'),
        ([[0, 0], [0]], r'expected q of shape \(7,\)'),
    ],
)
def test_single_rejects_bad_q(flexible, method, q, match):
    with pytest.raises(ValueError, match=match):
        getattr(flexible, method)(q)


@pytest.mark.parametrize('method', ['fk_batch', 'jacobian_batch', 'fk_and_jacobian_batch'])
@pytest.mark.parametrize(
    ('Q', 'match'),
    [
        (np.zeros(7), r'expected Q of shape \(N, 7\), got \(7,\)'),
        (np.zeros((4, 6)), r'expected Q of shape \(N, 7\), got \(4, 6\)'),
        (np.zeros((2, 4, 7)), r'expected Q of shape \(N, 7\), got \(2, 4, 7\)'),
        (np.full((3, 7), np.nan), r'expected Q to be finite'),
        ('abc', r'expected Q of shape \(N, 7\)'),
    ],
)
def test_batch_rejects_bad_configurations(flexible, method, Q, match):
    with pytest.raises(ValueError, match=match):
        getattr(flexible, method)(Q)


@pytest.mark.parametrize(
    ('q_m', 'q_k', 'match'),
    [
        (np.zeros(2), np.zeros(4), r'expected q_m of shape \(3,\), got \(2,\)'),
        (np.zeros(3), np.zeros(7), r'expected q_k of shape \(4,\), got \(7,\)'),
        ([0, np.nan, 0], np.zeros(4), r'expected q_m to be finite'),
        (np.zeros(3), [0, 0, np.inf, 0], r'expected q_k to be finite'),
    ],
)
def test_assemble_q_rejects_bad_input(q_m, q_k, match):
    with pytest.raises(ValueError, match=match):
        FlexibleArm.assemble_q(q_m, q_k)


def test_split_q_rejects_bad_input():
    with pytest.raises(ValueError, match=r'expected q of shape \(7,\), got \(3,\)'):
        FlexibleArm.split_q(np.zeros(3))


@pytest.mark.parametrize(
    ('table', 'names', 'match'),
    [
        (np.zeros((3, 2)), ['a', 'b', 'c'], r'expected dh_table of shape \(n, 3\)'),
        (np.zeros((0, 3)), [], r'expected dh_table of shape \(n, 3\)'),
        ([[0, 0, np.nan]], ['a'], r'expected dh_table to be finite'),
        (np.zeros((2, 3)), ['a'], r'expected joint_names of length 2'),
        (np.zeros((2, 3)), ['a', 'a'], r'expected unique joint_names'),
        (np.zeros((2, 3)), ['a', 'b"c'], r'expected joint_names to be identifiers'),
    ],
)
def test_dh_chain_rejects_bad_description(table, names, match):
    with pytest.raises(ValueError, match=match):
        DHChain(table, names)


def test_reference_rejects_bad_q():
    with pytest.raises(ValueError, match=r'expected q of shape \(7,\), got \(3,\)'):
        dh_fk_reference(flexible_dh_table(), np.zeros(3))


# --- the installed URDF: tip, limits, masses ---------------------------------------------------


def test_installed_urdf_is_the_generated_one():
    from pathlib import Path

    from ament_index_python.packages import get_package_share_directory

    from inflarm_model.urdf import URDF_FILENAME

    checked_in = Path(__file__).parents[2] / 'inflarm_model' / 'urdf' / URDF_FILENAME
    regenerate = 'python -m inflarm_model.urdf inflarm_model/urdf'
    assert checked_in.read_text(encoding='utf-8') == flexible_arm_urdf(), regenerate
    installed = Path(get_package_share_directory('inflarm_model')) / 'urdf' / URDF_FILENAME
    assert installed.read_text(encoding='utf-8') == flexible_arm_urdf(), 'scripts/setup.sh'


def test_urdf_limits_are_the_one_table():
    from inflarm_model.elastostatics import SPRING_DEFLECTION_LIMIT
    from inflarm_model.urdf import JOINT_LIMITS, MOTOR_MAX_EFFORT, MOTOR_MAX_VELOCITY

    root = ET.fromstring(flexible_arm_urdf())
    for joint in root.iter('joint'):
        if joint.get('type') != 'revolute':
            continue
        name, limit = joint.get('name'), joint.find('limit')
        assert (float(limit.get('lower')), float(limit.get('upper'))) == JOINT_LIMITS[name]
        if name in FlexibleArm.MOTOR_JOINT_NAMES:  # the simulated motors' rate limit
            assert float(limit.get('velocity')) == MOTOR_MAX_VELOCITY
            assert float(limit.get('effort')) == MOTOR_MAX_EFFORT
    for name in FlexibleArm.SPRING_JOINT_NAMES:  # the model range of the estimator
        assert JOINT_LIMITS[name] == (-SPRING_DEFLECTION_LIMIT, SPRING_DEFLECTION_LIMIT)
    # The tip link sits at DH frame 7, the end effector of eq. (4).
    model = pin.buildModelFromXML(flexible_arm_urdf())
    data = model.createData()
    q = random_q(np.random.default_rng(7), 7)
    pin.framesForwardKinematics(model, data, q)
    tip = model.getFrameId('tip', pin.BODY)
    np.testing.assert_allclose(data.oMf[tip].homogeneous,
                               dh_fk_reference(flexible_dh_table(), q), atol=TOL)
    np.testing.assert_allclose(model.lowerPositionLimit,
                               [JOINT_LIMITS[n][0] for n in FlexibleArm.JOINT_NAMES])


def test_urdf_masses_follow_the_stated_assumptions():
    from inflarm_model.urdf import CAP_MASS, FABRIC_DENSITY, segment_inertia

    model = pin.buildModelFromXML(flexible_arm_urdf())
    tube = 2 * math.pi * 0.055 * 0.5e-3 * L * FABRIC_DENSITY  # a whole link's fabric
    masses = {name: inertia.mass for name, inertia in zip(model.names, model.inertias,
                                                           strict=True)}
    link1 = masses['joint_2'] + masses['spring_2']  # bodies l1 and l2 of link 1
    link2 = masses['joint_3'] + masses['spring_4']
    assert link1 == pytest.approx(tube + 2 * CAP_MASS) == pytest.approx(link2)
    assert link1 == pytest.approx(0.295, abs=0.001)
    # A thin tube with no caps: the textbook inertias of a cylindrical shell.
    mass, center, axial, transverse = segment_inertia(0.6, 0.055, 0.5e-3, (0, 0))
    assert center == pytest.approx(0.3)
    assert axial == pytest.approx(mass * 0.055**2)
    assert transverse == pytest.approx(mass * (0.055**2 / 2 + 0.6**2 / 12))
    # The centre of mass of link 1's long body is past its middle: the distal cap.
    inertial = model.inertias[model.getJointId('spring_2')]
    assert inertial.lever[0] > L2 / 2
