"""Forward kinematics and geometric Jacobian of the inflatable-link arm.

Implements section 2.2 and eq. (4) of 000_ce37cf035a0a87c6 for the rigid 3-DOF arm (Table 1,
``RigidArm``) and the 7-DOF pseudo-rigid-body arm with virtual springs (Table 2,
``FlexibleArm``). Both are the same machinery, ``DHChain``, over a standard DH table,
T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), with every theta_i a joint variable.

Conventions: poses are 4x4 homogeneous transforms of the tip (DH frame n) in the base frame
(DH frame 0); Jacobians are geometric, linear rows first, in base-frame axes,
J_i = [z_{i-1} x (p_e - p_{i-1}); z_{i-1}] (eq. 4); columns follow the DH joint order.

Three independent implementations are kept, each checking the others in the tests:

- single configurations go through Pinocchio, built from the URDF of ``inflarm_model.urdf``;
- batches go through a vectorized numpy recursion on the frame axes;
- ``dh_fk_reference`` / ``dh_jacobian_reference`` are the textbook per-joint 4x4 chain.
"""

from collections.abc import Sequence
import math

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from inflarm_model.urdf import (
    DEFAULT_LINK_LENGTH,
    DEFAULT_SPRING_OFFSET,
    FLEXIBLE_JOINT_NAMES,
    MOTOR_JOINT_NAMES,
    RIGID_JOINT_NAMES,
    SPRING_JOINT_NAMES,
    TIP_LINK,
    check_dh_table,
    dh_chain_urdf,
    flexible_dh_table,
    rigid_dh_table,
)

__all__ = [
    'DHChain',
    'FlexibleArm',
    'RigidArm',
    'dh_fk_reference',
    'dh_frames_reference',
    'dh_jacobian_reference',
    'dh_transform',
]

# Bound once: module attribute lookups are a visible share of a ~2 us call.
_asarray = np.asarray
_isfinite = math.isfinite
_hypot = math.hypot
_frame_jacobian = pin.computeFrameJacobian
_frames_forward_kinematics = pin.framesForwardKinematics
_LOCAL_WORLD_ALIGNED = pin.LOCAL_WORLD_ALIGNED

_BATCH_CHUNK = 1024  # configurations per vectorized pass, see DHChain._fill_batch


def _vector(name: str, x: npt.ArrayLike, n: int) -> npt.NDArray[np.float64]:
    """Return ``x`` as a finite float array of shape (n,) or raise naming ``name``."""
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} of shape ({n},), got {x!r}') from None
    if v.shape != (n,):
        raise ValueError(f'expected {name} of shape ({n},), got {v.shape}')
    if not np.isfinite(v).all():
        raise ValueError(f'expected {name} to be finite, got {v}')
    return v


def _batch(name: str, X: npt.ArrayLike, n: int) -> npt.NDArray[np.float64]:
    """Return ``X`` as a finite float array of shape (N, n) or raise naming ``name``."""
    try:
        V = np.asarray(X, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} of shape (N, {n}), got {X!r}') from None
    if V.ndim != 2 or V.shape[1] != n:
        raise ValueError(f'expected {name} of shape (N, {n}), got {V.shape}')
    if not np.isfinite(V).all():
        raise ValueError(f'expected {name} to be finite, got non-finite entries')
    return V


def _joint_vector(q: npt.ArrayLike, shape: tuple[int]) -> npt.NDArray[np.float64]:
    """``_vector('q', q, n)`` at a fraction of the cost, for the per-call hot paths."""
    try:
        v = _asarray(q, dtype=float)
    except (TypeError, ValueError):
        return _vector('q', q, shape[0])
    # hypot is finite iff every entry is (unless finite entries overflow it, which _vector
    # then accepts): one C call on a list, a fifth of the cost of np.isfinite(v).all().
    if v.shape != shape or not _isfinite(_hypot(*v.tolist())):
        return _vector('q', q, shape[0])
    return v


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
    q = _vector('q', q, table.shape[0])
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


# --- the arms --------------------------------------------------------------------------------


class DHChain:
    """Serial revolute arm given by a standard DH table.

    Single configurations are evaluated with Pinocchio on a model built from the chain's URDF
    (``inflarm_model.urdf.dh_chain_urdf``); batches with a vectorized numpy recursion.

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

    Notes
    -----
    An instance owns one ``pinocchio.Data`` workspace: share an instance between threads only
    behind a lock, or build one per thread.
    """

    def __init__(self, dh_table: npt.ArrayLike, joint_names: Sequence[str]) -> None:
        table = check_dh_table(dh_table)
        table.setflags(write=False)
        self._dh_table = table
        self._n = n = table.shape[0]
        self._shape = (n,)
        self.joint_names: tuple[str, ...] = tuple(joint_names)
        self._model = pin.buildModelFromXML(
            dh_chain_urdf('inflarm_dh_chain', table, self.joint_names)
        )
        # Pinocchio numbers joints depth-first, which for a serial chain is the DH order; the
        # fast paths rely on it, so prove it once here rather than permute on every call.
        idx_q = [
            self._model.joints[self._model.getJointId(name)].idx_q for name in self.joint_names
        ]
        if self._model.nq != n or self._model.nv != n or idx_q != list(range(n)):
            raise RuntimeError(f'Pinocchio joint order {idx_q} differs from the DH order')
        self._data = self._model.createData()
        self._tip_id = self._model.getFrameId(TIP_LINK, pin.BODY)
        # A live reference into data.oMf, refreshed by every kinematic pass: indexing oMf on
        # every call would cost about 1 us.
        self._tip = self._data.oMf[self._tip_id]
        # Per-joint constants of the batch recursion. Twists of +-pi/2 (most of Table 2) are
        # taken as exact quarter turns, cos = 0 rather than 6e-17, to skip half the products.
        a, alpha, d = table.T
        ca, sa = np.cos(alpha), np.sin(alpha)
        ca[np.abs(ca) < 1e-15] = 0.0
        self._batch_rows = tuple(
            zip(a.tolist(), ca.tolist(), sa.tolist(), d.tolist(), strict=True)
        )

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return self._n

    @property
    def dh_table(self) -> npt.NDArray[np.float64]:
        """Read-only DH table, shape (n, 3), rows ``(a_i [m], alpha_i [rad], d_i [m])``."""
        return self._dh_table

    @property
    def model(self) -> pin.Model:
        """Pinocchio model of the chain; configuration and velocity in DH joint order."""
        return self._model

    @property
    def tip_frame_id(self) -> int:
        """Index of the ``tip`` frame (DH frame n) in ``model.frames``."""
        return self._tip_id

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
        q = _joint_vector(q, self._shape)
        _frames_forward_kinematics(self._model, self._data, q)
        return self._tip.homogeneous

    def jacobian(self, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Geometric Jacobian of eq. (4) at the tip, in the base frame.

        Parameters
        ----------
        q : array-like, shape (n,)
            Joint angles [rad] in DH order.

        Returns
        -------
        ndarray, shape (6, n)
            Linear rows [m/rad] first, then angular rows [rad/rad], base-frame axes; column i
            is ``[z_{i-1} x (p_e - p_{i-1}); z_{i-1}]``.

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        q = _joint_vector(q, self._shape)
        return _frame_jacobian(self._model, self._data, q, self._tip_id, _LOCAL_WORLD_ALIGNED)

    def fk_and_jacobian(
        self, q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Tip pose and geometric Jacobian from a single kinematic pass.

        The hot path of the load/pose estimator and the elastostatic IK (sections 2.3-2.4).

        Parameters
        ----------
        q : array-like, shape (n,)
            Joint angles [rad] in DH order.

        Returns
        -------
        pose : ndarray, shape (4, 4)
            Tip pose T_0^n in the base frame [m].
        jacobian : ndarray, shape (6, n)
            Geometric Jacobian of eq. (4), linear rows first, base-frame axes.

        Raises
        ------
        ValueError
            If ``q`` has the wrong shape or is not finite.
        """
        q = _joint_vector(q, self._shape)
        # computeFrameJacobian runs the forward pass and refreshes data.oMf[tip] too.
        J = _frame_jacobian(self._model, self._data, q, self._tip_id, _LOCAL_WORLD_ALIGNED)
        return self._tip.homogeneous, J

    def _frames_chunk(
        self, Q: npt.NDArray[np.float64]
    ) -> list[tuple[npt.NDArray[np.float64], ...]]:
        """Vectorized DH recursion on the frame axes for a chunk of configurations.

        With R_{i-1} = [x y z] (each axis a (3, N) array) and origin p_{i-1}, row i gives
        x' = c x + s y, y' = c y - s x (Rz(theta_i)), p_i = p_{i-1} + a_i x' + d_i z, then
        R_i = [x', ca y' + sa z, ca z - sa y'] (Rx(alpha_i)).

        Returns
        -------
        list of (x, y, z, p), length n + 1
            Axes and origin of DH frames 0..n, each of shape (3, N).
        """
        N = Q.shape[0]
        x, y, z = (np.repeat(e[:, None], N, axis=1) for e in np.eye(3))
        p = np.zeros((3, N))
        frames = [(x, y, z, p)]
        Qt = np.ascontiguousarray(Q.T)  # contiguous rows: the products below vectorize
        cos_q, sin_q = np.cos(Qt), np.sin(Qt)
        for i, (a, ca, sa, d) in enumerate(self._batch_rows):
            c, s = cos_q[i], sin_q[i]
            x, y = c * x + s * y, c * y - s * x
            if a != 0.0:
                p = p + a * x
            if d != 0.0:
                p = p + d * z
            if ca == 0.0:
                y, z = sa * z, -sa * y
            elif sa != 0.0:
                y, z = ca * y + sa * z, ca * z - sa * y
            frames.append((x, y, z, p))
        return frames

    def _fill_batch(
        self,
        Q: npt.NDArray[np.float64],
        poses: npt.NDArray[np.float64] | None,
        jacobians: npt.NDArray[np.float64] | None,
    ) -> None:
        """Write tip poses (N, 4, 4) and/or Jacobians (N, 6, n) of the rows of Q."""
        # Chunks keep the (3, chunk) temporaries in cache: on N = 10,000 in one pass, page
        # faults and cache misses on ~100 fresh 240 kB arrays cost more than the arithmetic.
        for start in range(0, Q.shape[0], _BATCH_CHUNK):
            stop = start + _BATCH_CHUNK
            frames = self._frames_chunk(Q[start:stop])
            x, y, z, p_e = frames[-1]
            if poses is not None:
                T = poses[start:stop]
                T[:, :3, 0] = x.T
                T[:, :3, 1] = y.T
                T[:, :3, 2] = z.T
                T[:, :3, 3] = p_e.T
                T[:, 3, :3] = 0.0
                T[:, 3, 3] = 1.0
            if jacobians is not None:
                # Eq. (4) for all joints at once: Z, R are (3, n, chunk) stacks of z_{i-1}
                # and p_e - p_{i-1}.
                Z = np.stack([f[2] for f in frames[:-1]], axis=1)
                R = p_e[:, None, :] - np.stack([f[3] for f in frames[:-1]], axis=1)
                J = jacobians[start:stop]
                J[:, 0] = (Z[1] * R[2] - Z[2] * R[1]).T
                J[:, 1] = (Z[2] * R[0] - Z[0] * R[2]).T
                J[:, 2] = (Z[0] * R[1] - Z[1] * R[0]).T
                J[:, 3:] = Z.transpose(2, 0, 1)

    def fk_batch(self, Q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Tip poses of many configurations, vectorized.

        Parameters
        ----------
        Q : array-like, shape (N, n)
            One configuration of joint angles [rad] per row, DH order.

        Returns
        -------
        ndarray, shape (N, 4, 4)
            Tip poses in the base frame [m].

        Raises
        ------
        ValueError
            If ``Q`` has the wrong shape or is not finite.
        """
        Q = _batch('Q', Q, self._n)
        poses = np.empty((Q.shape[0], 4, 4))
        self._fill_batch(Q, poses, None)
        return poses

    def jacobian_batch(self, Q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Geometric Jacobians (eq. 4) of many configurations, vectorized.

        Parameters
        ----------
        Q : array-like, shape (N, n)
            One configuration of joint angles [rad] per row, DH order.

        Returns
        -------
        ndarray, shape (N, 6, n)
            Jacobians, linear rows first, base-frame axes.

        Raises
        ------
        ValueError
            If ``Q`` has the wrong shape or is not finite.
        """
        Q = _batch('Q', Q, self._n)
        jacobians = np.empty((Q.shape[0], 6, self._n))
        self._fill_batch(Q, None, jacobians)
        return jacobians

    def fk_and_jacobian_batch(
        self, Q: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Tip poses and Jacobians of many configurations from one vectorized pass.

        Parameters
        ----------
        Q : array-like, shape (N, n)
            One configuration of joint angles [rad] per row, DH order.

        Returns
        -------
        poses : ndarray, shape (N, 4, 4)
            Tip poses in the base frame [m].
        jacobians : ndarray, shape (N, 6, n)
            Geometric Jacobians of eq. (4), linear rows first, base-frame axes.

        Raises
        ------
        ValueError
            If ``Q`` has the wrong shape or is not finite.
        """
        Q = _batch('Q', Q, self._n)
        poses = np.empty((Q.shape[0], 4, 4))
        jacobians = np.empty((Q.shape[0], 6, self._n))
        self._fill_batch(Q, poses, jacobians)
        return poses, jacobians

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
        q = _vector('q', q, self._n)
        return np.array([p[:, 0] for _, _, _, p in self._frames_chunk(q[None, :])])


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
    MOTOR_INDICES = (0, 1, 4)
    SPRING_INDICES = (2, 3, 5, 6)

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
        q[list(cls.MOTOR_INDICES)] = _vector('q_m', q_m, 3)
        q[list(cls.SPRING_INDICES)] = _vector('q_k', q_k, 4)
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
        q = _vector('q', q, 7)
        return q[list(cls.MOTOR_INDICES)], q[list(cls.SPRING_INDICES)]
