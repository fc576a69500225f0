"""Elastostatics of the inflatable-link arm: spring deflections under a tip load.

The forward problem of sections 2.3-2.4 of 000_ce37cf035a0a87c6, shared by the simulated arm,
the load and pose estimator (``inflarm_estimation.elastostatic``) and the elastostatic inverse
kinematics (``inflarm_control.elastostatic_ik``). Pure numpy/Pinocchio, no ROS.

Model
-----
``FlexibleArm`` (Table 2): q = (theta_1 .. theta_7) in DH order, motors q_m = q[0, 1, 4] (DH
joints 1, 2, 5), virtual springs q_k = q[2, 3, 5, 6] (DH joints 3, 4, 6, 7). A force f [N]
acts at the tip, tip moments are zero and there is no gravity (space), as in section 2.3.
J = [J_1 .. J_7] is the geometric Jacobian of eq. (4); only its linear rows U (3x7) meet a pure
force, so J^T gamma_e = U^T f.

Sign convention (stated here once; the estimator, the IK and the simulated arm all use it)
-------------------------------------------------------------------------------------------
We keep the paper's eqs (5)-(7) verbatim::

    tau = J^T gamma_e = U^T f              (5)  the load's generalized force on each joint
    tau_m = U_m^T f                        (6)  motor torques, DH joints 1, 2, 5
    tau_k = U_k^T f = k q_k                (7)  spring torques, DH joints 3, 4, 6, 7

tau_i [N·m] is the torque the tip load exerts about joint axis i (positive about +z_{i-1}),
i.e. the reaction torque the joint carries -- the paper's "measured" torque.

- Springs. Spring j pulls back with the elastic torque -k_j q_j; equilibrium is
  -k_j q_j + (U^T f)_j = 0, so ``k q_k = U_k^T f``. A force pushing the tip deflects the springs
  along it: the tip moves by U_k q_k = U_k K^-1 U_k^T f, whose dot product with f is positive.
- Motors. ``tau_m = U_m^T f`` is the load torque on each motor axis, the torque a joint torque
  sensor reports. The torque the motor itself applies to hold the load is ``-tau_m``.

Since U^T f is the gradient of f . p_e(q) (p_e the tip position), the equilibria are the
stationary points of the potential V(q_k) = 1/2 q_k^T K q_k - f . p_e(q), and the derivative
of the load torques is the load Hessian d(U^T f)/dq = d^2 (f . p_e) / dq^2, which for revolute
joints a <= b is ``H_ab = z_a . (u_b x f)`` (u_b column b of U, z_a axis of joint a). An
equilibrium is stable when K - H_kk is positive definite.

Solvers are Newton's method with a backtracking line search on the squared residual; they report
convergence, iterations and the final residual instead of returning silently wrong numbers.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math
import weakref

import numpy as np
import numpy.typing as npt
import pinocchio as pin

__all__ = [
    'DEFAULT_MAX_ITERATIONS',
    'DEFAULT_TOLERANCE',
    'MOTOR_INDICES',
    'SPRING_INDICES',
    'ArmKernel',
    'SpringEquilibrium',
    'SpringEquilibriumBatch',
    'arm_kernel',
    'check_rows',
    'check_stiffness',
    'check_vector',
    'flat_jacobian_batch',
    'float_list',
    'link_moments',
    'load_hessian',
    'motor_torques',
    'motor_torques_batch',
    'spring_deflections',
    'spring_deflections_batch',
    'spring_torques',
]

MOTOR_INDICES = (0, 1, 4)  # DH joints 1, 2, 5
SPRING_INDICES = (2, 3, 5, 6)  # DH joints 3, 4, 6, 7
# Equilibrium residual tolerance [N·m]: with k ~ 170 N·m/rad it pins q_k to ~1e-11 rad, yet
# stays well above rounding (1e-14 of torques up to ~100 N·m).
DEFAULT_TOLERANCE = 1e-9
DEFAULT_MAX_ITERATIONS = 50
_MAX_HALVINGS = 30  # backtracking line search: step lengths down to 2**-30
_ARMIJO = 1e-4

_frame_jacobian = pin.computeFrameJacobian
_LOCAL_WORLD_ALIGNED = pin.LOCAL_WORLD_ALIGNED
_isfinite = math.isfinite
_FLOAT64 = np.dtype(np.float64)


# --- validation ------------------------------------------------------------------------------


def check_vector(name: str, x: npt.ArrayLike, n: int, unit: str) -> npt.NDArray[np.float64]:
    """Return ``x`` as a finite float array of shape (n,) or raise naming ``name``."""
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} of shape ({n},) [{unit}], got {x!r}') from None
    if v.shape != (n,):
        raise ValueError(f'expected {name} of shape ({n},) [{unit}], got shape {v.shape}')
    if not np.isfinite(v).all():
        raise ValueError(f'expected {name} to be finite [{unit}], got {v}')
    return v


def float_list(name: str, x: npt.ArrayLike, n: int, unit: str) -> list[float]:
    """``x`` as a list of n finite Python floats, or raise ValueError naming ``name``.

    The hot-path form of the entry validation: a float ndarray of shape (n,) costs one
    ``tolist`` and one ``sum`` (the sum of floats is finite iff every term is, barring an
    overflow, which the slow path then sorts out).
    """
    if type(x) is np.ndarray and x.dtype is _FLOAT64 and x.shape == (n,):
        v = x.tolist()
        if _isfinite(sum(v)):
            return v
    return check_vector(name, x, n, unit).tolist()


def check_rows(name: str, X: npt.ArrayLike, n: int, unit: str) -> npt.NDArray[np.float64]:
    """Return ``X`` as a finite float array of shape (N, n) or raise naming ``name``."""
    try:
        V = np.asarray(X, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} of shape (N, {n}) [{unit}], got {X!r}') from None
    if V.ndim != 2 or V.shape[1] != n:
        raise ValueError(f'expected {name} of shape (N, {n}) [{unit}], got shape {V.shape}')
    if not np.isfinite(V).all():
        raise ValueError(f'expected {name} to be finite [{unit}], got non-finite entries')
    return V


def _rows_or_one(
    name: str, X: npt.ArrayLike, n: int, N: int, unit: str
) -> npt.NDArray[np.float64]:
    """Accept shape (n,) (one value shared by all N rows) or (N, n); return (N, n)."""
    if np.ndim(X) == 1:
        return np.broadcast_to(check_vector(name, X, n, unit), (N, n))
    V = check_rows(name, X, n, unit)
    if V.shape[0] != N:
        raise ValueError(f'expected {name} of shape ({n},) or ({N}, {n}) [{unit}], '
                         f'got shape {V.shape}')
    return V


def check_stiffness(stiffness: npt.ArrayLike) -> tuple[float, float, float, float]:
    """Validate a spring stiffness and return one value per spring.

    Parameters
    ----------
    stiffness : float or array-like, shape (4,)
        Virtual spring stiffness k [N·m/rad], one value shared by the four springs (the paper's
        k = k_3 = k_4 = k_6 = k_7) or one per spring in ``SPRING_INDICES`` order (the two
        orthogonal springs of a link may differ). Positive and finite.

    Returns
    -------
    tuple of 4 float
        (k_3, k_4, k_6, k_7) [N·m/rad].

    Raises
    ------
    ValueError
        If ``stiffness`` is not a scalar or of shape (4,), or not positive and finite.
    """
    if type(stiffness) is float and stiffness > 0.0 and _isfinite(stiffness):
        return stiffness, stiffness, stiffness, stiffness  # the common case, fast
    try:
        k = np.asarray(stiffness, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f'expected stiffness as a scalar or shape (4,) [N·m/rad], got {stiffness!r}'
        ) from None
    if k.shape == ():
        k = np.full(4, float(k))
    elif k.shape != (4,):
        raise ValueError(
            f'expected stiffness as a scalar or shape (4,) [N·m/rad], got shape {k.shape}'
        )
    if not (np.isfinite(k).all() and (k > 0.0).all()):
        raise ValueError(f'expected stiffness positive and finite [N·m/rad], got {k}')
    k0, k1, k2, k3 = k.tolist()
    return k0, k1, k2, k3


# --- the shared hot-path evaluator -----------------------------------------------------------


class ArmKernel:
    """Jacobian evaluations of one ``FlexibleArm`` without per-call validation.

    The hot path shared by the solvers here, the estimator and the IK: one Pinocchio pass per
    configuration, returned as a flat list of Python floats (small fixed-size algebra is faster
    in plain floats than through numpy calls). Get instances with ``arm_kernel(arm)``.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2; it must expose ``model`` (Pinocchio, DH joint order),
        ``tip_frame_id``, ``MOTOR_INDICES == (0, 1, 4)`` and ``SPRING_INDICES == (2, 3, 5, 6)``.

    Raises
    ------
    ValueError
        If ``arm`` is not a 7-joint arm with that motor/spring layout.

    Notes
    -----
    An instance owns a ``pinocchio.Data`` workspace: like the arm itself, share it between
    threads only behind a lock.
    """

    __slots__ = ('__weakref__', '_data', '_model', '_q', '_tip', '_tip_id')

    def __init__(self, arm: object) -> None:
        motors = tuple(getattr(arm, 'MOTOR_INDICES', ()))
        springs = tuple(getattr(arm, 'SPRING_INDICES', ()))
        model = getattr(arm, 'model', None)
        if motors != MOTOR_INDICES or springs != SPRING_INDICES or model is None or (
            model.nq != 7
        ):
            raise ValueError(
                'expected arm to be a FlexibleArm (7 joints, motors at DH indices (0, 1, 4), '
                f'springs at (2, 3, 5, 6)), got {type(arm).__name__}'
            )
        self._model = model
        self._data = model.createData()
        self._tip_id = arm.tip_frame_id
        self._q = np.zeros(7)
        # A live reference into data.oMf: computeFrameJacobian refreshes it on every pass.
        self._tip = self._data.oMf[self._tip_id]

    def jacobian_flat(
        self, m0: float, m1: float, k0: float, k1: float, m2: float, k2: float, k3: float
    ) -> list[float]:
        """Geometric Jacobian (eq. 4) at q = (m0, m1, k0, k1, m2, k2, k3), flattened.

        Returns
        -------
        list of 42 float
            Row-major 6x7: indices 0-6 the x row of U, 7-13 y, 14-20 z (linear [m/rad]), then
            the x, y, z rows of the joint axes (angular), base frame.
        """
        q = self._q
        q[0] = m0
        q[1] = m1
        q[4] = m2
        return self.spring_jacobian_flat(k0, k1, k2, k3)

    def set_motors(self, m0: float, m1: float, m2: float) -> None:
        """Hold the motor angles [rad] for the following ``spring_jacobian_flat`` calls."""
        q = self._q
        q[0] = m0
        q[1] = m1
        q[4] = m2

    def spring_jacobian_flat(self, k0: float, k1: float, k2: float, k3: float) -> list[float]:
        """``jacobian_flat`` at the held motor angles and these spring deflections [rad]."""
        q = self._q
        q[2] = k0
        q[3] = k1
        q[5] = k2
        q[6] = k3
        return _frame_jacobian(
            self._model, self._data, q, self._tip_id, _LOCAL_WORLD_ALIGNED
        ).ravel().tolist()

    def tip_position(self) -> list[float]:
        """Tip position [m], base frame, of the configuration last passed to jacobian_flat."""
        return self._tip.translation.tolist()


_KERNELS: 'weakref.WeakKeyDictionary[object, ArmKernel]' = weakref.WeakKeyDictionary()


def arm_kernel(arm: object) -> ArmKernel:
    """The cached ``ArmKernel`` of ``arm`` (built on first use, dropped with the arm).

    Raises
    ------
    ValueError
        If ``arm`` is not a FlexibleArm-like 7-joint arm (see ``ArmKernel``).
    """
    try:
        return _KERNELS[arm]
    except KeyError:
        kernel = _KERNELS[arm] = ArmKernel(arm)
        return kernel
    except TypeError:  # not weak-referenceable: build one, uncached
        return ArmKernel(arm)


# --- arithmetic on the flat Jacobian ---------------------------------------------------------
# Written once for Python floats (single solves) and numpy arrays of shape (N,) (batches): the
# flat Jacobian is then 42 arrays, one per entry.


def _spring_terms(j: Sequence, f0, f1, f2):
    """Spring load torques U_k^T f (eq. 7) and the spring block H_kk of the load Hessian.

    Returns ``(t3, t4, t6, t7, h22, h23, h25, h26, h33, h35, h36, h55, h56, h66)`` with DH
    (0-based) indices on the Hessian entries ``H_ab = z_a . (u_b x f)``.
    """
    (_, _, ux2, ux3, _, ux5, ux6,
     _, _, uy2, uy3, _, uy5, uy6,
     _, _, uz2, uz3, _, uz5, uz6,
     _, _, zx2, zx3, _, zx5, zx6,
     _, _, zy2, zy3, _, zy5, zy6,
     _, _, zz2, zz3, _, zz5, zz6) = j
    # v_b = u_b x f
    v2x, v2y, v2z = uy2 * f2 - uz2 * f1, uz2 * f0 - ux2 * f2, ux2 * f1 - uy2 * f0
    v3x, v3y, v3z = uy3 * f2 - uz3 * f1, uz3 * f0 - ux3 * f2, ux3 * f1 - uy3 * f0
    v5x, v5y, v5z = uy5 * f2 - uz5 * f1, uz5 * f0 - ux5 * f2, ux5 * f1 - uy5 * f0
    v6x, v6y, v6z = uy6 * f2 - uz6 * f1, uz6 * f0 - ux6 * f2, ux6 * f1 - uy6 * f0
    return (
        ux2 * f0 + uy2 * f1 + uz2 * f2,
        ux3 * f0 + uy3 * f1 + uz3 * f2,
        ux5 * f0 + uy5 * f1 + uz5 * f2,
        ux6 * f0 + uy6 * f1 + uz6 * f2,
        zx2 * v2x + zy2 * v2y + zz2 * v2z,
        zx2 * v3x + zy2 * v3y + zz2 * v3z,
        zx2 * v5x + zy2 * v5y + zz2 * v5z,
        zx2 * v6x + zy2 * v6y + zz2 * v6z,
        zx3 * v3x + zy3 * v3y + zz3 * v3z,
        zx3 * v5x + zy3 * v5y + zz3 * v5z,
        zx3 * v6x + zy3 * v6y + zz3 * v6z,
        zx5 * v5x + zy5 * v5y + zz5 * v5z,
        zx5 * v6x + zy5 * v6y + zz5 * v6z,
        zx6 * v6x + zy6 * v6y + zz6 * v6z,
    )


def _load_hessian_blocks(j: Sequence, f0, f1, f2):
    """Motor-spring and spring-spring blocks of the load Hessian, H_ab = z_a . (u_b x f).

    Returns ``(H_mk, H_kk)``: H_mk as 12 values, rows DH 0, 1, 4 by columns DH 2, 3, 5, 6,
    and the 10 unique values (h22, h23, h25, h26, h33, h35, h36, h55, h56, h66) of H_kk.
    """
    (_, _, ux2, ux3, ux4, ux5, ux6,
     _, _, uy2, uy3, uy4, uy5, uy6,
     _, _, uz2, uz3, uz4, uz5, uz6,
     _, zx1, zx2, zx3, zx4, zx5, zx6,
     _, zy1, zy2, zy3, zy4, zy5, zy6,
     _, zz1, zz2, zz3, zz4, zz5, zz6) = j
    v2x, v2y, v2z = uy2 * f2 - uz2 * f1, uz2 * f0 - ux2 * f2, ux2 * f1 - uy2 * f0
    v3x, v3y, v3z = uy3 * f2 - uz3 * f1, uz3 * f0 - ux3 * f2, ux3 * f1 - uy3 * f0
    v4x, v4y, v4z = uy4 * f2 - uz4 * f1, uz4 * f0 - ux4 * f2, ux4 * f1 - uy4 * f0
    v5x, v5y, v5z = uy5 * f2 - uz5 * f1, uz5 * f0 - ux5 * f2, ux5 * f1 - uy5 * f0
    v6x, v6y, v6z = uy6 * f2 - uz6 * f1, uz6 * f0 - ux6 * f2, ux6 * f1 - uy6 * f0
    # Joint 1 turns about z_0, the base z axis (DH frame 0), so H_0b = v_b . e_z.
    h_mk = (
        v2z, v3z, v5z, v6z,
        zx1 * v2x + zy1 * v2y + zz1 * v2z, zx1 * v3x + zy1 * v3y + zz1 * v3z,
        zx1 * v5x + zy1 * v5y + zz1 * v5z, zx1 * v6x + zy1 * v6y + zz1 * v6z,
        zx2 * v4x + zy2 * v4y + zz2 * v4z, zx3 * v4x + zy3 * v4y + zz3 * v4z,
        zx4 * v5x + zy4 * v5y + zz4 * v5z, zx4 * v6x + zy4 * v6y + zz4 * v6z,
    )
    h_kk = (
        zx2 * v2x + zy2 * v2y + zz2 * v2z, zx2 * v3x + zy2 * v3y + zz2 * v3z,
        zx2 * v5x + zy2 * v5y + zz2 * v5z, zx2 * v6x + zy2 * v6y + zz2 * v6z,
        zx3 * v3x + zy3 * v3y + zz3 * v3z, zx3 * v5x + zy3 * v5y + zz3 * v5z,
        zx3 * v6x + zy3 * v6y + zz3 * v6z, zx5 * v5x + zy5 * v5y + zz5 * v5z,
        zx5 * v6x + zy5 * v6y + zz5 * v6z, zx6 * v6x + zy6 * v6y + zz6 * v6z,
    )
    return h_mk, h_kk


def _spring_torques_flat(j: Sequence, f0, f1, f2):
    """U_k^T f: the load torques on the four springs (eq. 7)."""
    return (
        j[2] * f0 + j[9] * f1 + j[16] * f2,
        j[3] * f0 + j[10] * f1 + j[17] * f2,
        j[5] * f0 + j[12] * f1 + j[19] * f2,
        j[6] * f0 + j[13] * f1 + j[20] * f2,
    )


def _cholesky_solve4(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33, b0, b1, b2, b3):
    """Solve the symmetric 4x4 system A x = b by LDL^T.

    Returns ``(x0, x1, x2, x3, d_min)`` with d_min the smallest pivot of D (A is positive
    definite iff d_min > 0). Works elementwise on arrays.
    """
    d0 = a00
    l10 = a01 / d0
    l20 = a02 / d0
    l30 = a03 / d0
    d1 = a11 - l10 * a01
    l21 = (a12 - l20 * a01) / d1
    l31 = (a13 - l30 * a01) / d1
    d2 = a22 - l20 * a02 - l21 * l21 * d1
    l32 = (a23 - l30 * a02 - l31 * l21 * d1) / d2
    d3 = a33 - l30 * a03 - l31 * l31 * d1 - l32 * l32 * d2
    y0 = b0
    y1 = b1 - l10 * y0
    y2 = b2 - l20 * y0 - l21 * y1
    y3 = b3 - l30 * y0 - l31 * y1 - l32 * y2
    x3 = y3 / d3
    x2 = y2 / d2 - l32 * x3
    x1 = y1 / d1 - l21 * x2 - l31 * x3
    x0 = y0 / d0 - l10 * x1 - l20 * x2 - l30 * x3
    if isinstance(d0, float):
        d_min = min(d0, d1, d2, d3)
    else:
        d_min = np.minimum(np.minimum(d0, d1), np.minimum(d2, d3))
    return x0, x1, x2, x3, d_min


def _surely_stable(j: Sequence, f0, f1, f2, k_min):
    """Cheap sufficient test that K - H_kk is positive definite (elementwise on arrays).

    |H_ab| <= |f| |u_max(a,b)|, so the Frobenius norm of H_kk is at most |f| sqrt(sum), the
    sum over the 4x4 spring block of |u|^2 of the more distal joint of each pair.
    """
    n2 = (f0 * f0 + f1 * f1 + f2 * f2) * (
        (j[2] * j[2] + j[9] * j[9] + j[16] * j[16])
        + 3.0 * (j[3] * j[3] + j[10] * j[10] + j[17] * j[17])
        + 5.0 * (j[5] * j[5] + j[12] * j[12] + j[19] * j[19])
        + 7.0 * (j[6] * j[6] + j[13] * j[13] + j[20] * j[20])
    )
    return n2 < k_min * k_min


def _stable(j: Sequence, f0, f1, f2, k0, k1, k2, k3):
    """K - H_kk positive definite: the equilibrium is stable (elementwise on arrays)."""
    (_, _, _, _, h22, h23, h25, h26, h33, h35, h36, h55, h56, h66) = _spring_terms(j, f0, f1, f2)
    zero = 0.0 * f0
    *_, d_min = _cholesky_solve4(k0 - h22, -h23, -h25, -h26, k1 - h33, -h35, -h36, k2 - h55,
                                 -h56, k3 - h66, zero, zero, zero, zero)
    return d_min > 0.0


# --- forward problem: deflections under a known load -----------------------------------------


@dataclass(frozen=True)
class SpringEquilibrium:
    """Spring deflections of the loaded arm, the solution of k q_k = U_k^T f (eqs 5-7).

    Attributes
    ----------
    q_k : ndarray, shape (4,)
        Spring deflections [rad], DH joints 3, 4, 6, 7; NaN unless ``converged``.
    tau_k : ndarray, shape (4,)
        Spring torques k q_k [N·m] (eq. 7); NaN unless ``converged``.
    tip_position : ndarray, shape (3,)
        Deflected tip position [m], base frame; NaN unless ``converged``.
    converged : bool
        True when the residual reached the tolerance at a stable equilibrium.
    iterations : int
        Newton iterations taken.
    residual : float
        max |k q_k - U_k^T f| [N·m] at the last iterate.
    status : str
        ``'converged'``, ``'max_iterations'``, ``'line_search'`` (no descent step found) or
        ``'unstable'`` (K - H_kk not positive definite: load beyond the stability limit).
    """

    q_k: npt.NDArray[np.float64]
    tau_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    converged: bool
    iterations: int
    residual: float
    status: str


def _solve_springs(kernel: ArmKernel, m0: float, m1: float, m2: float, f0: float, f1: float,
                   f2: float, k0: float, k1: float, k2: float, k3: float, q0: float, q1: float,
                   q2: float, q3: float, tol: float, max_iterations: int):
    """Newton's method on g(q_k) = K q_k - U_k^T f with backtracking on |g|^2.

    Returns ``(q0, q1, q2, q3, j, iterations, residual, status)`` where ``j`` is the flat
    Jacobian at the returned configuration.
    """
    j = kernel.jacobian_flat(m0, m1, q0, q1, m2, q2, q3)
    t0, t1, t2, t3 = _spring_torques_flat(j, f0, f1, f2)
    g0, g1, g2, g3 = k0 * q0 - t0, k1 * q1 - t1, k2 * q2 - t2, k3 * q3 - t3
    merit = g0 * g0 + g1 * g1 + g2 * g2 + g3 * g3
    iterations = 0
    while True:
        residual = max(abs(g0), abs(g1), abs(g2), abs(g3))
        if residual <= tol:
            # Newton's steps ensure it along the way, but a start that already balances the
            # load (e.g. a straight arm under axial compression) must be checked.
            if not (_surely_stable(j, f0, f1, f2, min(k0, k1, k2, k3))
                    or _stable(j, f0, f1, f2, k0, k1, k2, k3)):
                return q0, q1, q2, q3, j, iterations, residual, 'unstable'
            return q0, q1, q2, q3, j, iterations, residual, 'converged'
        if iterations >= max_iterations:
            return q0, q1, q2, q3, j, iterations, residual, 'max_iterations'
        iterations += 1
        (_, _, _, _, h22, h23, h25, h26, h33, h35, h36, h55, h56, h66) = _spring_terms(
            j, f0, f1, f2)
        d0, d1, d2, d3, d_min = _cholesky_solve4(
            k0 - h22, -h23, -h25, -h26, k1 - h33, -h35, -h36, k2 - h55, -h56, k3 - h66,
            -g0, -g1, -g2, -g3)
        if not d_min > 0.0:
            return q0, q1, q2, q3, j, iterations, residual, 'unstable'
        alpha = 1.0
        for _ in range(_MAX_HALVINGS):
            p0, p1, p2, p3 = q0 + alpha * d0, q1 + alpha * d1, q2 + alpha * d2, q3 + alpha * d3
            jt = kernel.jacobian_flat(m0, m1, p0, p1, m2, p2, p3)
            t0, t1, t2, t3 = _spring_torques_flat(jt, f0, f1, f2)
            e0, e1, e2, e3 = k0 * p0 - t0, k1 * p1 - t1, k2 * p2 - t2, k3 * p3 - t3
            trial = e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3
            if trial <= (1.0 - 2.0 * _ARMIJO * alpha) * merit:
                break
            alpha *= 0.5
        else:
            return q0, q1, q2, q3, j, iterations, residual, 'line_search'
        q0, q1, q2, q3, j, merit = p0, p1, p2, p3, jt, trial
        g0, g1, g2, g3 = e0, e1, e2, e3


def spring_deflections(
    arm: object,
    q_m: npt.ArrayLike,
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    q_k0: npt.ArrayLike | None = None,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> SpringEquilibrium:
    """Spring deflections of the arm holding a tip force, eqs (5)-(7) of 000_ce37cf035a0a87c6.

    Solves the equilibrium ``k q_k = U_k(q_m, q_k)^T f`` (nonlinear in q_k through the
    Jacobian) by Newton's method on the residual with the analytic load Hessian and a
    backtracking line search. Up to 100 N on the paper's arm (k = 172.71 N·m/rad) the
    equilibrium is unique and stable (K - H_kk stays positive definite) and Newton converges
    from q_k = 0 in 3-6 iterations.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_m : array-like, shape (3,)
        Motor angles [rad], DH joints 1, 2, 5.
    force : array-like, shape (3,)
        Tip force f [N], base frame.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or per spring (see ``check_stiffness``).
    q_k0 : array-like, shape (4,), optional
        Initial guess [rad] (warm start); zeros by default.
    tol : float, optional
        Residual tolerance max |k q_k - U_k^T f| [N·m], positive.
    max_iterations : int, optional
        Newton iterations allowed, >= 1.

    Returns
    -------
    SpringEquilibrium
        Deflections, spring torques, deflected tip and diagnostics; the arrays are NaN when
        ``converged`` is False.

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values, non-positive stiffness or
        tolerances.
    """
    kernel = arm_kernel(arm)
    m0, m1, m2 = float_list('q_m', q_m, 3, 'rad')
    f0, f1, f2 = float_list('force', force, 3, 'N')
    k0, k1, k2, k3 = check_stiffness(stiffness)
    q0, q1, q2, q3 = (0.0,) * 4 if q_k0 is None else float_list('q_k0', q_k0, 4, 'rad')
    tol, max_iterations = _check_solver_options(tol, max_iterations)
    q0, q1, q2, q3, _, iterations, residual, status = _solve_springs(
        kernel, m0, m1, m2, f0, f1, f2, k0, k1, k2, k3, q0, q1, q2, q3, tol, max_iterations)
    if status != 'converged':
        nan = np.full(4, np.nan)
        return SpringEquilibrium(nan, nan.copy(), np.full(3, np.nan), False, iterations,
                                 residual, status)
    return SpringEquilibrium(
        np.array((q0, q1, q2, q3)),
        np.array((k0 * q0, k1 * q1, k2 * q2, k3 * q3)),
        np.array(kernel.tip_position()),
        True, iterations, residual, status,
    )


def _check_solver_options(tol: float, max_iterations: int) -> tuple[float, int]:
    tol = float(tol)
    if not (_isfinite(tol) and tol > 0.0):
        raise ValueError(f'expected tol positive and finite [N·m], got {tol!r}')
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise ValueError(f'expected max_iterations an integer >= 1, got {max_iterations!r}')
    return tol, int(max_iterations)


# --- forward problem, vectorized over N ------------------------------------------------------


@dataclass(frozen=True)
class SpringEquilibriumBatch:
    """Spring deflections of N loaded configurations (see ``SpringEquilibrium``).

    Attributes
    ----------
    q_k : ndarray, shape (N, 4)
        Spring deflections [rad]; NaN rows where not converged.
    tau_k : ndarray, shape (N, 4)
        Spring torques k q_k [N·m]; NaN rows where not converged.
    tip_position : ndarray, shape (N, 3)
        Deflected tip positions [m], base frame; NaN rows where not converged.
    converged : ndarray of bool, shape (N,)
    iterations : ndarray of int, shape (N,)
    residual : ndarray, shape (N,)
        max |k q_k - U_k^T f| [N·m] at the last iterate.
    status : ndarray of str, shape (N,)
        As ``SpringEquilibrium.status``.
    """

    q_k: npt.NDArray[np.float64]
    tau_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    converged: npt.NDArray[np.bool_]
    iterations: npt.NDArray[np.int64]
    residual: npt.NDArray[np.float64]
    status: npt.NDArray[np.str_]


def flat_jacobian_batch(arm: object, Q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Jacobians of the rows of Q (N, 7) as 42 rows of length N (the flat layout, vectorized)."""
    J = arm.jacobian_batch(Q)
    return np.ascontiguousarray(J.reshape(len(Q), 42).T)


def spring_deflections_batch(
    arm: object,
    Q_m: npt.ArrayLike,
    forces: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    Q_k0: npt.ArrayLike | None = None,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> SpringEquilibriumBatch:
    """``spring_deflections`` for N configurations at once, vectorized with numpy.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    Q_m : array-like, shape (N, 3)
        Motor angles [rad], one configuration per row.
    forces : array-like, shape (3,) or (N, 3)
        Tip forces [N], base frame; one shared force or one per row.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].
    Q_k0 : array-like, shape (N, 4), optional
        Initial guesses [rad]; zeros by default.
    tol, max_iterations
        As in ``spring_deflections``.

    Returns
    -------
    SpringEquilibriumBatch

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values or non-positive stiffness.
    """
    arm_kernel(arm)  # validates the arm layout
    Q_m = check_rows('Q_m', Q_m, 3, 'rad')
    N = Q_m.shape[0]
    F = _rows_or_one('forces', forces, 3, N, 'N')
    k = np.array(check_stiffness(stiffness))
    Q_k = np.zeros((N, 4)) if Q_k0 is None else _rows_or_one('Q_k0', Q_k0, 4, N, 'rad').copy()
    tol, max_iterations = _check_solver_options(tol, max_iterations)

    Q = np.zeros((N, 7))
    Q[:, MOTOR_INDICES] = Q_m
    Q[:, SPRING_INDICES] = Q_k
    iterations = np.zeros(N, dtype=np.int64)
    residual = np.full(N, np.inf)
    status = np.full(N, 'max_iterations', dtype='<U14')
    k_col = k[:, None]

    def residuals(idx, Qi):
        j = flat_jacobian_batch(arm, Qi)
        t = np.array(_spring_torques_flat(j, *F[idx].T))
        return j, k_col * Qi[:, SPRING_INDICES].T - t  # (4, n)

    active = np.arange(N)
    j, g = residuals(active, Q)
    for _ in range(max_iterations + 1):
        res = np.abs(g).max(axis=0)
        residual[active] = res
        done = res <= tol
        status[active[done]] = 'converged'
        keep = ~done & (iterations[active] < max_iterations)
        active, j, g = active[keep], j[:, keep], g[:, keep]
        if active.size == 0:
            break
        iterations[active] += 1
        f0, f1, f2 = F[active].T
        (_, _, _, _, h22, h23, h25, h26, h33, h35, h36, h55, h56, h66) = _spring_terms(
            j, f0, f1, f2)
        d0, d1, d2, d3, d_min = _cholesky_solve4(
            k[0] - h22, -h23, -h25, -h26, k[1] - h33, -h35, -h36, k[2] - h55, -h56,
            k[3] - h66, -g[0], -g[1], -g[2], -g[3])
        unstable = ~(d_min > 0.0)
        status[active[unstable]] = 'unstable'
        d = np.array((d0, d1, d2, d3))
        stable = ~unstable
        active, j, g, d = active[stable], j[:, stable], g[:, stable], d[:, stable]
        merit = (g * g).sum(axis=0)
        alpha = np.ones(active.size)
        pending = np.arange(active.size)
        new_j, new_g = np.empty_like(j), np.empty_like(g)
        for _ in range(_MAX_HALVINGS):
            idx = active[pending]
            Qt = Q[idx].copy()
            Qt[:, SPRING_INDICES] += alpha[pending, None] * d[:, pending].T
            jt, gt = residuals(idx, Qt)
            ok = (gt * gt).sum(axis=0) <= (1.0 - 2.0 * _ARMIJO * alpha[pending]) * merit[pending]
            accepted = pending[ok]
            Q[active[accepted]] = Qt[ok]
            new_j[:, accepted], new_g[:, accepted] = jt[:, ok], gt[:, ok]
            pending = pending[~ok]
            if pending.size == 0:
                break
            alpha[pending] *= 0.5
        failed = np.zeros(active.size, dtype=bool)
        failed[pending] = True
        status[active[failed]] = 'line_search'
        active, j, g = active[~failed], new_j[:, ~failed], new_g[:, ~failed]

    idx = np.flatnonzero(status == 'converged')
    if idx.size:  # stability, as in the single form
        j = flat_jacobian_batch(arm, Q[idx])
        f0, f1, f2 = F[idx].T
        stable = _surely_stable(j, f0, f1, f2, k.min())
        rest = ~stable
        stable[rest] = _stable(j[:, rest], f0[rest], f1[rest], f2[rest], *k)
        status[idx[~stable]] = 'unstable'
    converged = status == 'converged'
    Q_k = Q[:, SPRING_INDICES].copy()
    tips = arm.fk_batch(Q)[:, :3, 3]
    Q_k[~converged] = np.nan
    tips[~converged] = np.nan
    return SpringEquilibriumBatch(Q_k, Q_k * k, tips, converged, iterations, residual, status)


# --- load torques, moments and the load Hessian ----------------------------------------------


def _q7(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    return check_vector('q', q, 7, 'rad')


def motor_torques(arm: object, q: npt.ArrayLike, force: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Motor torques that hold a tip force, tau_m = U_m(q)^T f, eq. (6) of 000_ce37cf035a0a87c6.

    In the convention of this module's docstring: the load torque about each motor axis (the
    torque a joint sensor reports); the motor itself applies ``-tau_m``.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,)
        Joint angles [rad], DH order, spring deflections included (at equilibrium for a
        physically consistent state).
    force : array-like, shape (3,)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (3,)
        tau_m [N·m] on DH joints 1, 2, 5.

    Raises
    ------
    ValueError
        If ``q`` or ``force`` has the wrong shape or is not finite.
    """
    q = _q7(q)
    f = check_vector('force', force, 3, 'N')
    U = arm.jacobian(q)[:3]
    return U[:, MOTOR_INDICES].T @ f


def motor_torques_batch(
    arm: object, Q: npt.ArrayLike, forces: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """``motor_torques`` for N configurations, vectorized.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    Q : array-like, shape (N, 7)
        Joint angles [rad], one configuration per row.
    forces : array-like, shape (3,) or (N, 3)
        Tip forces [N], base frame.

    Returns
    -------
    ndarray, shape (N, 3)
        tau_m [N·m] on DH joints 1, 2, 5.

    Raises
    ------
    ValueError
        On arguments of the wrong shape or non-finite values.
    """
    Q = check_rows('Q', Q, 7, 'rad')
    F = _rows_or_one('forces', forces, 3, Q.shape[0], 'N')
    U = arm.jacobian_batch(Q)[:, :3, :]
    return np.einsum('nij,ni->nj', U[:, :, MOTOR_INDICES], F)


def spring_torques(
    arm: object, q: npt.ArrayLike, force: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Load torques on the springs, U_k(q)^T f (eq. 5 restricted to DH joints 3, 4, 6, 7).

    At equilibrium they equal k q_k (eq. 7).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,) or (N, 7)
        Joint angles [rad], DH order.
    force : array-like, shape (3,) or (N, 3)
        Tip force(s) f [N], base frame.

    Returns
    -------
    ndarray, shape (4,) or (N, 4)
        Spring torques [N·m].

    Raises
    ------
    ValueError
        On arguments of the wrong shape or non-finite values.
    """
    q_arr = np.asarray(q, dtype=float)
    if q_arr.ndim == 1:
        U = arm.jacobian(_q7(q_arr))[:3]
        return U[:, SPRING_INDICES].T @ check_vector('force', force, 3, 'N')
    Q = check_rows('q', q_arr, 7, 'rad')
    F = _rows_or_one('force', force, 3, Q.shape[0], 'N')
    U = arm.jacobian_batch(Q)[:, :3, :]
    return np.einsum('nij,ni->nj', U[:, :, SPRING_INDICES], F)


def link_moments(
    arm: object, q: npt.ArrayLike, force: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Bending moment on each inflatable link at its virtual springs.

    The two orthogonal springs of a link carry the two components of the link's bending
    moment; their combination ``sqrt(tau_a**2 + tau_b**2)`` is the moment section 4 of
    000_ce37cf035a0a87c6 compares with the wrinkling moment of eq. (3) ("the maximum moment on
    link 1 ... resulting from the combination of the torques acting on the two orthogonal
    virtual springs").

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,) or (N, 7)
        Joint angles [rad], DH order, spring deflections included.
    force : array-like, shape (3,) or (N, 3)
        Tip force(s) f [N], base frame.

    Returns
    -------
    ndarray, shape (2,) or (N, 2)
        Moments [N·m] on link 1 (springs DH 3, 4) and link 2 (springs DH 6, 7).

    Raises
    ------
    ValueError
        On arguments of the wrong shape or non-finite values.
    """
    t = spring_torques(arm, q, force)
    return np.stack([np.hypot(t[..., 0], t[..., 1]), np.hypot(t[..., 2], t[..., 3])], axis=-1)


def load_hessian(
    arm: object, q: npt.ArrayLike, force: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Derivative of the load torques U(q)^T f with respect to q (f held constant).

    ``H = d(U^T f)/dq = d^2 (f . p_e)/dq^2``; for revolute joints a <= b,
    ``H_ab = z_a . (u_b x f)`` with z_a the axis of joint a and u_b the linear Jacobian column
    of joint b (eq. 4). It is the geometric stiffness of the load: the equilibrium of eq. (7)
    is stable when K - H_kk is positive definite.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,)
        Joint angles [rad], DH order.
    force : array-like, shape (3,)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (7, 7)
        Symmetric H [N·m/rad], DH order.

    Raises
    ------
    ValueError
        If ``q`` or ``force`` has the wrong shape or is not finite.
    """
    J = arm.jacobian(_q7(q))
    f = check_vector('force', force, 3, 'N')
    U, Z = J[:3], J[3:]
    skew = np.array([[0.0, -f[2], f[1]], [f[2], 0.0, -f[0]], [-f[1], f[0], 0.0]])
    # M[a, b] = (f x z_a) . u_b = z_a . (u_b x f), valid for a <= b.
    M = (skew @ Z).T @ U
    upper = np.triu(M)
    return upper + np.triu(M, 1).T
