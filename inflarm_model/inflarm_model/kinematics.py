"""Forward kinematics and geometric Jacobian of the inflatable-link arm.

Implements section 2.2 and eq. (4) of 000_ce37cf035a0a87c6 for the rigid 3-DOF arm (Table 1,
``RigidArm``) and the 7-DOF pseudo-rigid-body arm with virtual springs (Table 2,
``FlexibleArm``). Both are the same machinery, ``DHChain``, over a standard DH table,
T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), with every theta_i a joint variable.

Conventions: poses are 4x4 homogeneous transforms of the tip (DH frame n) in the base frame
(DH frame 0); Jacobians are geometric, linear rows first, in base-frame axes,
J_i = [z_{i-1} x (p_e - p_{i-1}); z_{i-1}] (eq. 4); columns follow the DH joint order.

One implementation evaluates the arm: ``dh_chain_kinematics``, the DH recursion on the frame
axes compiled with numba, for a single configuration and for every row of a batch alike (and
inside the compiled elastostatic solvers of ``inflarm_model.elastostatics``). Two independent
ones check it in the tests: Pinocchio on the URDF the robot publishes (``DHChain.model``, built
by ``inflarm_model.urdf``), and ``dh_fk_reference`` / ``dh_jacobian_reference``, the textbook
per-joint 4x4 chain.
"""

from collections.abc import Sequence
from functools import cached_property
import math

from numba import njit
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from inflarm_model.urdf import (
    DEFAULT_LINK_LENGTH,
    DEFAULT_SPRING_OFFSET,
    FLEXIBLE_JOINT_NAMES,
    MOTOR_INDICES,
    MOTOR_JOINT_NAMES,
    RIGID_JOINT_NAMES,
    SPRING_INDICES,
    SPRING_JOINT_NAMES,
    TIP_LINK,
    check_dh_table,
    check_joint_names,
    dh_chain_urdf,
    flexible_dh_table,
    rigid_dh_table,
)
from inflarm_model.validation import check_rows, check_vector

__all__ = [
    'DHChain',
    'FlexibleArm',
    'RigidArm',
    'dh_fk_reference',
    'dh_frames_reference',
    'dh_chain_kinematics',
    'dh_jacobian_reference',
    'dh_transform',
]

# Index arrays of MOTOR_INDICES and SPRING_INDICES: numpy fancy indexing takes an integer array
# without converting a list on every call.
_MOTOR_INDEX, _SPRING_INDEX = np.array(MOTOR_INDICES), np.array(SPRING_INDICES)


# --- reference implementation: plain per-joint DH chain --------------------------------------


def dh_transform(a: float, alpha: float, d: float, theta: float) -> npt.NDArray[np.float64]:
    """Homogeneous transform of one standard DH row, Rz(theta) Tz(d) Tx(a) Rx(alpha).

    Parameters
    ----------
    a : float
        Link length [m].
    alpha : float
        Link twist [rad].
    d : float
        Link offset [m].
    theta : float
        Joint angle [rad].

    Returns
    -------
    ndarray, shape (4, 4)
        Pose of frame i in frame i-1.
    """
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def dh_frames_reference(
    dh_table: npt.ArrayLike, q: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Poses of all DH frames by chaining 4x4 products, one joint at a time.

    Reference implementation (slow, obviously correct) for tests and benchmarks.

    Parameters
    ----------
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])``.
    q : array-like, shape (n,)
        Joint angles theta_i [rad].

    Returns
    -------
    ndarray, shape (n + 1, 4, 4)
        T_0^0 = I, T_0^1, ..., T_0^n in the base frame; the last is the tip pose.

    Raises
    ------
    ValueError
        On a malformed table, or ``q`` of the wrong shape or not finite.
    """
    table = check_dh_table(dh_table)
    q = check_vector('q', q, table.shape[0])
    frames = [np.eye(4)]
    for (a, alpha, d), theta in zip(table, q, strict=True):
        frames.append(frames[-1] @ dh_transform(a, alpha, d, theta))
    return np.array(frames)


def dh_fk_reference(dh_table: npt.ArrayLike, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Tip pose T_0^n of a DH chain by plain 4x4 products (reference implementation).

    Parameters
    ----------
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])``.
    q : array-like, shape (n,)
        Joint angles [rad].

    Returns
    -------
    ndarray, shape (4, 4)
        Tip pose in the base frame.

    Raises
    ------
    ValueError
        On a malformed table, or ``q`` of the wrong shape or not finite.
    """
    return dh_frames_reference(dh_table, q)[-1]


def dh_jacobian_reference(
    dh_table: npt.ArrayLike, q: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Geometric Jacobian of eq. (4) assembled column by column (reference implementation).

    Parameters
    ----------
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])``.
    q : array-like, shape (n,)
        Joint angles [rad].

    Returns
    -------
    ndarray, shape (6, n)
        Column i is ``[z_{i-1} x (p_e - p_{i-1}); z_{i-1}]`` in the base frame, mapping joint
        rates [rad/s] to tip linear [m/s] and angular [rad/s] velocity.

    Raises
    ------
    ValueError
        On a malformed table, or ``q`` of the wrong shape or not finite.
    """
    frames = dh_frames_reference(dh_table, q)
    p_e = frames[-1][:3, 3]
    J = np.empty((6, len(frames) - 1))
    for i, T in enumerate(frames[:-1]):
        z, p = T[:3, 2], T[:3, 3]
        J[3:, i] = z
        J[:3, i] = p_e - p  # crossed with the z axes below, all columns in one call
    J[:3] = np.cross(J[3:], J[:3], axis=0)
    return J


# --- compiled recursion ----------------------------------------------------------------------


@njit(cache=True)
def dh_chain_kinematics(dh_table, q, pose, jacobian, origins):
    """Tip pose, geometric Jacobian (eq. 4) and frame origins of one configuration.

    The DH recursion on the frame axes: with R_{i-1} = [x y z] and origin p_{i-1}, row i gives
    x' = c x + s y, y' = c y - s x (Rz(theta_i)), p_i = p_{i-1} + a_i x' + d_i z, then
    R_i = [x', ca y' + sa z, ca z - sa y'] (Rx(alpha_i)); J_i = [z_{i-1} x (p_e - p_{i-1});
    z_{i-1}]. Compiled with numba (nopython); callable from Python and from compiled code.

    Parameters
    ----------
    dh_table : ndarray, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])`` (``check_dh_table``).
    q : ndarray, shape (n,)
        Joint angles [rad], finite.
    pose : ndarray, shape (4, 4)
        Output: tip pose T_0^n in the base frame [m].
    jacobian : ndarray, shape (6, n)
        Output: linear rows [m/rad] then joint axes, base-frame axes.
    origins : ndarray, shape (n + 1, 3)
        Output: origins of DH frames 0..n [m], base frame.
    """
    n = dh_table.shape[0]
    x0, x1, x2 = 1.0, 0.0, 0.0
    y0, y1, y2 = 0.0, 1.0, 0.0
    z0, z1, z2 = 0.0, 0.0, 1.0
    p0, p1, p2 = 0.0, 0.0, 0.0
    origins[0, 0], origins[0, 1], origins[0, 2] = 0.0, 0.0, 0.0
    for i in range(n):
        jacobian[3, i], jacobian[4, i], jacobian[5, i] = z0, z1, z2
        a, alpha, d = dh_table[i, 0], dh_table[i, 1], dh_table[i, 2]
        c, s = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(alpha), math.sin(alpha)
        x0, x1, x2, y0, y1, y2 = (c * x0 + s * y0, c * x1 + s * y1, c * x2 + s * y2,
                                  c * y0 - s * x0, c * y1 - s * x1, c * y2 - s * x2)
        p0, p1, p2 = p0 + a * x0 + d * z0, p1 + a * x1 + d * z1, p2 + a * x2 + d * z2
        y0, y1, y2, z0, z1, z2 = (ca * y0 + sa * z0, ca * y1 + sa * z1, ca * y2 + sa * z2,
                                  ca * z0 - sa * y0, ca * z1 - sa * y1, ca * z2 - sa * y2)
        origins[i + 1, 0], origins[i + 1, 1], origins[i + 1, 2] = p0, p1, p2
    for i in range(n):
        r0 = p0 - origins[i, 0]
        r1 = p1 - origins[i, 1]
        r2 = p2 - origins[i, 2]
        a0, a1, a2 = jacobian[3, i], jacobian[4, i], jacobian[5, i]
        jacobian[0, i] = a1 * r2 - a2 * r1
        jacobian[1, i] = a2 * r0 - a0 * r2
        jacobian[2, i] = a0 * r1 - a1 * r0
    pose[0, 0], pose[1, 0], pose[2, 0] = x0, x1, x2
    pose[0, 1], pose[1, 1], pose[2, 1] = y0, y1, y2
    pose[0, 2], pose[1, 2], pose[2, 2] = z0, z1, z2
    pose[0, 3], pose[1, 3], pose[2, 3] = p0, p1, p2
    pose[3, 0], pose[3, 1], pose[3, 2], pose[3, 3] = 0.0, 0.0, 0.0, 1.0


@njit(cache=True)
def _dh_chain_rows(dh_table, Q, poses, jacobians):
    """``dh_chain_kinematics`` of every row of Q (N, n) into poses (N, 4, 4), J (N, 6, n)."""
    origins = np.empty((dh_table.shape[0] + 1, 3))
    for i in range(Q.shape[0]):
        dh_chain_kinematics(dh_table, Q[i], poses[i], jacobians[i], origins)


# --- the arms --------------------------------------------------------------------------------


class DHChain:
    """Serial revolute arm given by a standard DH table.

    Every configuration, single or in a batch, is evaluated by the compiled recursion
    ``dh_chain_kinematics``; ``model`` is the same chain in Pinocchio, built from its URDF
    (``inflarm_model.urdf.dh_chain_urdf``).

    Parameters
    ----------
    dh_table : array-like, shape (n, 3)
        Rows ``(a_i [m], alpha_i [rad], d_i [m])``, T_i = Rz(theta_i) Tz(d_i) Tx(a_i)
        Rx(alpha_i).
    joint_names : sequence of str, length n
        Joint names in DH order, as in the URDF and on ``joint_states``.

    Raises
    ------
    ValueError
        On a malformed table or joint names.
    """

    def __init__(self, dh_table: npt.ArrayLike, joint_names: Sequence[str]) -> None:
        table = check_dh_table(dh_table)
        table.setflags(write=False)
        self._dh_table = table
        self._n = n = table.shape[0]
        self.joint_names: tuple[str, ...] = check_joint_names(joint_names, n)

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return self._n

    @property
    def dh_table(self) -> npt.NDArray[np.float64]:
        """Read-only DH table, shape (n, 3), rows ``(a_i [m], alpha_i [rad], d_i [m])``."""
        return self._dh_table

    @cached_property
    def model(self) -> pin.Model:
        """Pinocchio model of the chain, from its URDF; configuration and velocity in DH joint
        order (checked when it is built)."""
        model = pin.buildModelFromXML(
            dh_chain_urdf('inflarm_dh_chain', self._dh_table, self.joint_names))
        # Pinocchio numbers joints depth-first, which for a serial chain is the DH order.
        idx_q = [model.joints[model.getJointId(name)].idx_q for name in self.joint_names]
        if model.nq != self._n or model.nv != self._n or idx_q != list(range(self._n)):
            raise RuntimeError(f'Pinocchio joint order {idx_q} differs from the DH order')
        return model

    @property
    def tip_frame_id(self) -> int:
        """Index of the ``tip`` frame (DH frame n) in ``model.frames``."""
        return self.model.getFrameId(TIP_LINK, pin.BODY)

    def _pass(self, q: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], ...]:
        """Tip pose (4, 4), Jacobian (6, n) and frame origins (n + 1, 3) of one configuration."""
        q = check_vector('q', q, self._n)
        pose = np.empty((4, 4))
        jacobian = np.empty((6, self._n))
        origins = np.empty((self._n + 1, 3))
        dh_chain_kinematics(self._dh_table, q, pose, jacobian, origins)
        return pose, jacobian, origins

    def fk(self, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Tip pose in the base frame.

        Parameters
        ----------
        q : array-like, shape (n,)
            Joint angles [rad] in DH order.

        Returns
        -------
        ndarray, shape (4, 4)
            Homogeneous transform T_0^n of the tip in the base frame [m].

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        return self._pass(q)[0]

    def jacobian(self, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Geometric Jacobian of eq. (4) at the tip, in the base frame, at the joint angles
        ``q`` of ``fk``: shape (6, n), linear rows [m/rad] first, then angular rows [rad/rad],
        base-frame axes; column i is ``[z_{i-1} x (p_e - p_{i-1}); z_{i-1}]``. ``ValueError``
        as ``fk``."""
        return self._pass(q)[1]

    def fk_and_jacobian(
        self, q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(fk(q), jacobian(q))`` from a single kinematic pass: the hot path of the
        load/pose estimator and the elastostatic IK (sections 2.3-2.4). ``ValueError`` as
        ``fk``."""
        pose, jacobian, _ = self._pass(q)
        return pose, jacobian

    def _batch_pass(
        self, Q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Tip poses (N, 4, 4) and Jacobians (N, 6, n) of the rows of Q, compiled."""
        Q = np.ascontiguousarray(check_rows('Q', Q, self._n))
        poses = np.empty((Q.shape[0], 4, 4))
        jacobians = np.empty((Q.shape[0], 6, self._n))
        _dh_chain_rows(self._dh_table, Q, poses, jacobians)
        return poses, jacobians

    def fk_batch(self, Q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """``fk`` of every row of ``Q`` (N, n) [rad], in one compiled pass: shape (N, 4, 4).
        ``ValueError`` if ``Q`` has the wrong shape or is not finite."""
        return self._batch_pass(Q)[0]

    def jacobian_batch(self, Q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """``jacobian`` of every row of ``Q`` (N, n) [rad], in one compiled pass: shape
        (N, 6, n). ``ValueError`` if ``Q`` has the wrong shape or is not finite."""
        return self._batch_pass(Q)[1]

    def fk_and_jacobian_batch(
        self, Q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``fk_and_jacobian`` of every row of ``Q`` (N, n) [rad], in one compiled pass:
        poses (N, 4, 4) and Jacobians (N, 6, n). ``ValueError`` if ``Q`` has the wrong shape or
        is not finite."""
        return self._batch_pass(Q)

    def joint_origins(self, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Origins of the base, every DH frame and the tip, for plots and collision checks.

        Parameters
        ----------
        q : array-like, shape (n,)
            Joint angles [rad] in DH order.

        Returns
        -------
        ndarray, shape (n + 1, 3)
            Row k is the origin of DH frame k in the base frame [m]: row 0 the base, row n the
            tip. Row k (k < n) is also where joint k + 1 sits.

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        return self._pass(q)[2]


class RigidArm(DHChain):
    """Rigid 3-DOF arm with two links of length L, Table 1 of 000_ce37cf035a0a87c6.

    Parameters
    ----------
    link_length : float
        Link length L [m], positive and finite.

    Raises
    ------
    ValueError
        If ``link_length`` is not a positive finite number.
    """

    JOINT_NAMES = RIGID_JOINT_NAMES
    MOTOR_JOINT_NAMES = RIGID_JOINT_NAMES
    MOTOR_INDICES = (0, 1, 2)

    def __init__(self, link_length: float = DEFAULT_LINK_LENGTH) -> None:
        super().__init__(rigid_dh_table(link_length), self.JOINT_NAMES)
        self._link_length = float(link_length)

    @property
    def link_length(self) -> float:
        """Link length L [m]."""
        return self._link_length


class FlexibleArm(DHChain):
    """7-DOF pseudo-rigid-body arm, Table 2 of 000_ce37cf035a0a87c6.

    Each inflatable link of length L is two rigid bodies, l1 = ``spring_offset`` and
    l2 = L - l1, joined by two orthogonal virtual springs (section 2.2). In DH order the
    joints are motor, motor, spring, spring, motor, spring, spring: q_m = q[MOTOR_INDICES]
    (DH joints 1, 2, 5), q_k = q[SPRING_INDICES] (DH joints 3, 4, 6, 7).

    Parameters
    ----------
    link_length : float
        Inflatable link length L [m], positive and finite.
    spring_offset : float
        l1 [m], ``0 < spring_offset < link_length``.

    Raises
    ------
    ValueError
        If a length is not positive and finite or ``spring_offset >= link_length``.
    """

    JOINT_NAMES = FLEXIBLE_JOINT_NAMES
    MOTOR_JOINT_NAMES = MOTOR_JOINT_NAMES
    SPRING_JOINT_NAMES = SPRING_JOINT_NAMES
    MOTOR_INDICES = MOTOR_INDICES
    SPRING_INDICES = SPRING_INDICES

    def __init__(
        self,
        link_length: float = DEFAULT_LINK_LENGTH,
        spring_offset: float = DEFAULT_SPRING_OFFSET,
    ) -> None:
        super().__init__(flexible_dh_table(link_length, spring_offset), self.JOINT_NAMES)
        self._link_length = float(link_length)
        self._spring_offset = float(spring_offset)

    @property
    def link_length(self) -> float:
        """Inflatable link length L [m]."""
        return self._link_length

    @property
    def spring_offset(self) -> float:
        """l1 [m], distance of the virtual springs from the proximal joint of a link."""
        return self._spring_offset

    @classmethod
    def assemble_q(cls, q_m: npt.ArrayLike, q_k: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Full joint vector from motor and spring angles.

        Parameters
        ----------
        q_m : array-like, shape (3,)
            Motor angles [rad] ``(theta_1, theta_2, theta_5)``.
        q_k : array-like, shape (4,)
            Virtual spring deflections [rad] ``(theta_3, theta_4, theta_6, theta_7)``.

        Returns
        -------
        ndarray, shape (7,)
            q in DH order.

        Raises
        ------
        ValueError
            If an argument has the wrong shape or is not finite.
        """
        q = np.empty(7)
        q[_MOTOR_INDEX] = check_vector('q_m', q_m, 3)
        q[_SPRING_INDEX] = check_vector('q_k', q_k, 4)
        return q

    @classmethod
    def split_q(
        cls, q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Motor and spring angles of a full joint vector.

        Parameters
        ----------
        q : array-like, shape (7,)
            Joint angles [rad] in DH order.

        Returns
        -------
        q_m : ndarray, shape (3,)
            Motor angles [rad] (DH joints 1, 2, 5).
        q_k : ndarray, shape (4,)
            Spring deflections [rad] (DH joints 3, 4, 6, 7).

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        q = check_vector('q', q, 7)
        return q[_MOTOR_INDEX], q[_SPRING_INDEX]
