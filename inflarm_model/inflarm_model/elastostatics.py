"""Elastostatics of the inflatable-link arm: eqs (4)-(7) and the solvers of Fig. 5.

The one implementation of sections 2.3-2.4 of 000_ce37cf035a0a87c6, shared by the simulated
arm (``inflarm_hw.inflatable_arm_sim``), the load and pose estimator
(``inflarm_estimation.elastostatic``) and the elastostatic inverse kinematics
(``inflarm_control.elastostatic_ik``). Pure numpy/Pinocchio, no ROS.

Model
-----
``FlexibleArm`` (Table 2): q = (theta_1 .. theta_7) in DH order, motors q_m = q[MOTOR_INDICES]
(DH joints 1, 2, 5), virtual springs q_k = q[SPRING_INDICES] (DH joints 3, 4, 6, 7). A force f
[N] acts at the tip, tip moments are zero and there is no gravity (space), as in section 2.3.
J = [J_1 .. J_7] is the geometric Jacobian of eq. (4); only its linear rows U (3x7) meet a pure
force, so J^T gamma_e = U^T f.

Sign convention (stated here once; the estimator, the IK and the simulated arm all use it)
-------------------------------------------------------------------------------------------
The paper's eqs (5)-(7) verbatim::

    tau = J^T gamma_e = U^T f              (5)  the load's generalized force on each joint
    tau_m = U_m^T f                        (6)  motor torques, DH joints 1, 2, 5
    tau_k = U_k^T f = k q_k                (7)  spring torques, DH joints 3, 4, 6, 7

tau_i [N·m] is the torque the tip load exerts about joint axis i (positive about +z_{i-1}),
i.e. the reaction torque the joint carries. A force pushing the tip deflects the springs along
it. The torque a motor applies to hold the load is ``-tau_m`` (what ros2_control reports as
``joint_states.effort``): negate at the ROS edge, never in these functions.

Since U^T f is the gradient of f . p_e(q), the equilibria are the stationary points of the
potential V(q_k) = 1/2 q_k^T K q_k - f . p_e(q), and the load Hessian
``H = d(U^T f)/dq = d^2 (f . p_e)/dq^2`` has, for revolute joints a <= b,
``H_ab = z_a . (u_b x f)``. An equilibrium is stable when K - H_kk is positive definite.

Every function broadcasts over leading batch dimensions (q of shape (..., 7), Jacobians
(..., 6, 7), forces (..., 3)); a single configuration is a batch of one.

Solvers
-------
``spring_deflections`` solves eq. (7) for q_k under a known force (the forward problem).
``solve_load_fixed_point`` (Fig. 5 verbatim), ``solve_load_newton`` and
``solve_load_continuation`` solve eqs (6)-(7) for f and q_k from q_m and tau_m (the inverse
problem). All return an ``ElastostaticSolution`` and report convergence, iterations and the
final residual instead of returning silently wrong numbers: the arrays are NaN where a sample
did not converge.
"""

from dataclasses import dataclass
import math

from numba import guvectorize, njit
import numpy as np
import numpy.typing as npt

from inflarm_model.kinematics import dh_chain_kinematics
from inflarm_model.urdf import (
    DEFAULT_STIFFNESS,
    MOTOR_INDICES,
    SPRING_DEFLECTION_LIMIT,
    SPRING_INDICES,
)
from inflarm_model.validation import check_batch

__all__ = [
    'DEFAULT_MAX_ITERATIONS',
    'DEFAULT_TOLERANCE',
    'MAX_NEWTON_STEP',
    'MOTOR_INDICES',
    'SPRING_DEFLECTION_LIMIT',
    'SPRING_INDICES',
    'STATUS_NAMES',
    'ElastostaticSolution',
    'check_arm',
    'check_solver_options',
    'check_stiffness',
    'conditioning',
    'conditioning_sample',
    'equilibrium_stiffness',
    'link_moments',
    'load_hessian',
    'load_torques',
    'motor_load',
    'motor_torques',
    'newton_load_sample',
    'reduced_newton_matrix',
    'solve_load_continuation',
    'solve_load_fixed_point',
    'solve_load_newton',
    'spring_deflections',
    'spring_residual',
    'spring_torques',
    'stable',
    'tip_position_and_jacobian',
    'warm_up',
]

# Equilibrium residual tolerance max |k q_k - U_k^T f| [N·m]: with k ~ 170 N·m/rad it pins q_k
# to ~1e-12 rad and an estimated force to ~1e-9 N, well above rounding (1e-14 of torques up to
# ~100 N·m). The one tolerance of every solver here and of the estimator.
DEFAULT_TOLERANCE = 1e-10
DEFAULT_MAX_ITERATIONS = 50
# Largest Newton correction per spring and iteration [rad]: a longer step is shortened to it.
MAX_NEWTON_STEP = 0.25
_MAX_HALVINGS = 20  # backtracking line search: step lengths down to 2**-20
_ARMIJO = 1e-4
# Iterates beyond twice the model range are abandoned as diverged [rad].
_DIVERGED = 2.0 * SPRING_DEFLECTION_LIMIT
_M = MOTOR_INDICES  # tuples: compile-time constants in the numba kernels
_S = SPRING_INDICES
# Compiled once, then loaded from the on-disk cache; floats divide as in numpy (inf, NaN),
# never raising, so that a singular sample is reported instead of stopping a batch.
_JIT = dict(cache=True, error_model='numpy')


# --- validation ------------------------------------------------------------------------------


def check_stiffness(stiffness: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Validate a spring stiffness and return one value per spring.

    Parameters
    ----------
    stiffness : float or array-like, shape (4,)
        Virtual spring stiffness k [N·m/rad], one value shared by the four springs (the paper's
        k = k_3 = k_4 = k_6 = k_7) or one per spring in ``SPRING_INDICES`` order (the two
        orthogonal springs of a link may differ). Positive and finite.

    Returns
    -------
    ndarray, shape (4,)
        (k_3, k_4, k_6, k_7) [N·m/rad].

    Raises
    ------
    ValueError
        If ``stiffness`` is not a scalar or of shape (4,), or not positive and finite.
    """
    if isinstance(stiffness, float) and stiffness > 0.0 and math.isfinite(stiffness):
        return np.full(4, stiffness)  # the common cases, fast
    if (isinstance(stiffness, np.ndarray) and stiffness.shape == (4,)
            and stiffness.dtype == np.float64 and stiffness.min() > 0.0
            and math.isfinite(stiffness.sum())):
        return stiffness
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
    return k


def check_solver_options(tol: float, max_iterations: int) -> tuple[float, int]:
    """Validate a residual tolerance [N·m] and an iteration limit; return them typed."""
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        tol = math.nan
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f'expected tol positive and finite [N·m], got {tol!r}')
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) \
            or max_iterations < 1:
        raise ValueError(f'expected max_iterations an integer >= 1, got {max_iterations!r}')
    return tol, int(max_iterations)


def check_arm(arm: object) -> None:
    """Raise ValueError unless ``arm`` is a FlexibleArm-like 7-joint arm.

    The functions here need ``fk_and_jacobian`` and ``fk_and_jacobian_batch`` (eq. 4) and the
    motor/spring layout ``MOTOR_INDICES``, ``SPRING_INDICES`` of Table 2.
    """
    if (getattr(arm, 'MOTOR_INDICES', None) != MOTOR_INDICES
            or getattr(arm, 'SPRING_INDICES', None) != SPRING_INDICES
            or getattr(arm, 'n_joints', None) != 7):
        raise ValueError(
            f'expected arm to be a FlexibleArm (7 joints, motors at DH indices {MOTOR_INDICES},'
            f' springs at {SPRING_INDICES}), got {type(arm).__name__}')


def _broadcast(*arrays: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], ...]:
    """Broadcast arrays of shapes (..., n_i) over their leading dimensions."""
    shapes = [a.shape[:-1] for a in arrays]
    if all(shape == shapes[0] for shape in shapes):
        return arrays
    try:
        shape = np.broadcast_shapes(*shapes)
    except ValueError:
        raise ValueError('expected arguments whose leading (batch) dimensions broadcast, got '
                         f'shapes {[a.shape for a in arrays]}') from None
    return tuple(np.broadcast_to(a, shape + a.shape[-1:]) for a in arrays)


# --- eq. (4): the tip Jacobian ---------------------------------------------------------------


def tip_position_and_jacobian(
    arm: object, q: npt.ArrayLike
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Tip position and geometric Jacobian, eq. (4) of 000_ce37cf035a0a87c6.

    Evaluated by ``inflarm_model.kinematics.dh_chain_kinematics``, the kinematics of the
    compiled solvers below (the kinematics tests hold it equal to Pinocchio and to the textbook
    chain).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (..., 7)
        Joint angles [rad], DH order.

    Returns
    -------
    position : ndarray, shape (..., 3)
        Tip position p_e [m], base frame.
    jacobian : ndarray, shape (..., 6, 7)
        J: rows 0-2 the linear rows U, ``u_i = z_{i-1} x (p_e - p_{i-1})`` [m/rad]; rows 3-5
        the joint axes z_{i-1}; base-frame axes.

    Raises
    ------
    ValueError
        If ``arm`` is not a FlexibleArm or ``q`` is not finite of shape (..., 7).
    """
    check_arm(arm)
    q = check_batch('q', q, 7, 'rad')
    poses, J = arm.fk_and_jacobian_batch(q.reshape(-1, 7))
    return poses[:, :3, 3].reshape(q.shape[:-1] + (3,)), J.reshape(q.shape[:-1] + (6, 7))


# --- compiled kernels of eqs (5)-(7), one sample each ----------------------------------------
# The one implementation of each equation. The public functions below broadcast them over
# leading batch dimensions (numba gufuncs); the solvers call them inside compiled loops.


@njit(**_JIT)
def _load_torques(J, f, tau):
    for j in range(J.shape[1]):
        tau[j] = J[0, j] * f[0] + J[1, j] * f[1] + J[2, j] * f[2]


@njit(**_JIT)
def _spring_residual(J, f, q_k, k, g):
    for s in range(4):
        j = _S[s]
        g[s] = k[s] * q_k[s] - (J[0, j] * f[0] + J[1, j] * f[1] + J[2, j] * f[2])


@njit(**_JIT)
def _inverse_motor_transpose(J, inverse):
    """(U_m^T)^-1 by the adjugate: U_m^T has rows a, b, c = u_1, u_2, u_5, so its inverse has
    columns (b x c, c x a, a x b) / det, det = a . (b x c). Returns det (0: singular)."""
    a, b, c = _M
    for col, (r1, r2) in enumerate(((b, c), (c, a), (a, b))):
        inverse[0, col] = J[1, r1] * J[2, r2] - J[2, r1] * J[1, r2]
        inverse[1, col] = J[2, r1] * J[0, r2] - J[0, r1] * J[2, r2]
        inverse[2, col] = J[0, r1] * J[1, r2] - J[1, r1] * J[0, r2]
    det = J[0, a] * inverse[0, 0] + J[1, a] * inverse[1, 0] + J[2, a] * inverse[2, 0]
    for i in range(3):
        for col in range(3):
            inverse[i, col] /= det
    return det


@njit(**_JIT)
def _motor_load(J, tau, f):
    inverse = np.empty((3, 3))
    det = _inverse_motor_transpose(J, inverse)
    for i in range(3):
        f[i] = inverse[i, 0] * tau[0] + inverse[i, 1] * tau[1] + inverse[i, 2] * tau[2]
    return det


@njit(**_JIT)
def _load_hessian(J, f, H):
    n = J.shape[1]
    for b in range(n):
        vx = J[1, b] * f[2] - J[2, b] * f[1]  # u_b x f
        vy = J[2, b] * f[0] - J[0, b] * f[2]
        vz = J[0, b] * f[1] - J[1, b] * f[0]
        for a in range(b + 1):
            H[a, b] = H[b, a] = J[3, a] * vx + J[4, a] * vy + J[5, a] * vz


@njit(**_JIT)
def _equilibrium_stiffness(H, k, A):
    for r in range(4):
        for c in range(4):
            A[r, c] = -H[_S[r], _S[c]]
        A[r, r] += k[r]


@njit(**_JIT)
def _reduced_newton_matrix(J, H, k, D):
    inverse = np.empty((3, 3))
    _inverse_motor_transpose(J, inverse)
    _equilibrium_stiffness(H, k, D)
    for c in range(4):
        x0 = x1 = x2 = 0.0  # column c of X = U_m^-T H_mk
        for i in range(3):
            h = H[_M[i], _S[c]]
            x0 += inverse[0, i] * h
            x1 += inverse[1, i] * h
            x2 += inverse[2, i] * h
        for r in range(4):
            j = _S[r]
            D[r, c] += J[0, j] * x0 + J[1, j] * x1 + J[2, j] * x2


@njit(**_JIT)
def _positive_definite(A):
    """Cholesky of the symmetric 4x4 A succeeds."""
    L = np.zeros((4, 4))
    for j in range(4):
        s = A[j, j]
        for p in range(j):
            s -= L[j, p] * L[j, p]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, 4):
            t = A[i, j]
            for p in range(j):
                t -= L[i, p] * L[j, p]
            L[i, j] = t / L[j, j]
    return True


@njit(**_JIT)
def _solve4(A, b, x):
    """x = A^-1 b by Gaussian elimination with partial pivoting; False if A is singular."""
    M = A.copy()
    y = b.copy()
    for c in range(4):
        p = c
        for r in range(c + 1, 4):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if not abs(M[p, c]) > 0.0:  # singular, or NaN
            return False
        if p != c:
            for j in range(4):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            y[c], y[p] = y[p], y[c]
        for r in range(c + 1, 4):
            m = M[r, c] / M[c, c]
            for j in range(c, 4):
                M[r, j] -= m * M[c, j]
            y[r] -= m * y[c]
    for r in range(3, -1, -1):
        t = y[r]
        for j in range(r + 1, 4):
            t -= M[r, j] * x[j]
        x[r] = t / M[r, r]
    return True


# --- public broadcasting forms ---------------------------------------------------------------

_GU = dict(nopython=True, cache=True)


@guvectorize(['void(f8[:, :], f8[:], f8[:])'], '(r,n),(c)->(n)', **_GU)
def _load_torques_gu(J, f, tau):
    _load_torques(J, f, tau)


@guvectorize(['void(f8[:, :], f8[:], f8[:], f8[:], f8[:])'], '(r,n),(c),(s),(s)->(s)', **_GU)
def _spring_residual_gu(J, f, q_k, k, g):
    _spring_residual(J, f, q_k, k, g)


@guvectorize(['void(f8[:, :], f8[:], f8[:])'], '(r,n),(c)->(c)', **_GU)
def _motor_load_gu(J, tau, f):
    _motor_load(J, tau, f)


@guvectorize(['void(f8[:, :], f8[:], f8[:, :])'], '(r,n),(c)->(n,n)', **_GU)
def _load_hessian_gu(J, f, H):
    _load_hessian(J, f, H)


@guvectorize(['void(f8[:, :], f8[:], f8[:, :])'], '(n,n),(s)->(s,s)', **_GU)
def _equilibrium_stiffness_gu(H, k, A):
    _equilibrium_stiffness(H, k, A)


@guvectorize(['void(f8[:, :], f8[:, :], f8[:], f8[:, :])'], '(r,n),(n,n),(s)->(s,s)', **_GU)
def _reduced_newton_matrix_gu(J, H, k, D):
    _reduced_newton_matrix(J, H, k, D)


@guvectorize(['void(f8[:, :], f8[:], b1[:])'], '(n,n),(s)->()', **_GU)
def _stable_gu(H, k, out):
    A = np.empty((4, 4))
    _equilibrium_stiffness(H, k, A)
    out[0] = _positive_definite(A)


@njit(**_JIT)
def conditioning_sample(J, f, k, direction):
    """``conditioning`` of one sample, for compiled callers (a numba kernel).

    Parameters
    ----------
    J : ndarray, shape (6, 7)
        Tip Jacobian.
    f : ndarray, shape (3,)
        Tip force [N].
    k : ndarray, shape (4,)
        Stiffness [N·m/rad].
    direction : ndarray, shape (4,)
        Output: the right singular vector of D's smallest singular value (zeros if D is not
        finite).

    Returns
    -------
    condition, sigma : float
        The condition number of U_m (inf where singular or not finite) and D's smallest
        singular value (NaN where D is not finite).
    """
    U_m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            U_m[i, j] = J[i, _M[j]]
    condition, sigma = np.inf, np.nan
    direction[:] = 0.0
    if not np.isfinite(U_m).all():  # LAPACK refuses NaN
        return condition, sigma
    singular = np.linalg.svd(U_m)[1]
    if singular[2] > 0.0:
        condition = singular[0] / singular[2]
    H, D = np.empty((7, 7)), np.empty((4, 4))
    _load_hessian(J, f, H)
    _reduced_newton_matrix(J, H, k, D)
    if np.isfinite(D).all():
        _, values, vt = np.linalg.svd(D)
        sigma = values[3]
        direction[:] = vt[3]
    return condition, sigma


@guvectorize(['void(f8[:, :], f8[:], f8[:], f8[:], f8[:], f8[:])'], '(r,n),(c),(s)->(),(),(s)',
             **_GU)
def _conditioning_gu(J, f, k, condition, sigma, direction):
    condition[0], sigma[0] = conditioning_sample(J, f, k, direction)


def _f8(x: npt.ArrayLike) -> npt.NDArray[np.float64]:
    return np.asarray(x, dtype=np.float64)


def load_torques(jacobian: npt.ArrayLike, force: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Generalized force of the tip load on every joint, tau = U^T f, eq. (5) of 000_....

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian (``tip_position_and_jacobian``); only the linear rows U are used.
    force : array-like, shape (..., 3)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (..., 7)
        tau [N·m], DH order: tau[..., MOTOR_INDICES] is tau_m (eq. 6), tau[..., SPRING_INDICES]
        the spring load torques U_k^T f (eq. 7).
    """
    return _load_torques_gu(_f8(jacobian), _f8(force))


def spring_residual(
    jacobian: npt.ArrayLike, force: npt.ArrayLike, q_k: npt.ArrayLike,
    stiffness: npt.ArrayLike,
) -> npt.NDArray[np.float64]:
    """Spring equilibrium residual k q_k - U_k^T f, eq. (7) of 000_ce37cf035a0a87c6.

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian at q = (q_m, q_k).
    force : array-like, shape (..., 3)
        Tip force f [N], base frame.
    q_k : array-like, shape (..., 4)
        Spring deflections [rad], DH joints 3, 4, 6, 7.
    stiffness : array-like, shape (4,)
        k [N·m/rad] (``check_stiffness``).

    Returns
    -------
    ndarray, shape (..., 4)
        [N·m]; zero at an equilibrium.
    """
    return _spring_residual_gu(_f8(jacobian), _f8(force), _f8(q_k), _f8(stiffness))


def motor_load(jacobian: npt.ArrayLike, tau_m: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The force that eq. (6) gives for motor torques: f solving U_m^T f = tau_m.

    The rigid step of Fig. 5 of 000_ce37cf035a0a87c6, solved by the adjugate: it never
    raises, and where U_m is singular the result is not finite.

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian at q = (q_m, q_k).
    tau_m : array-like, shape (..., 3)
        Motor torques [N·m], DH joints 1, 2, 5 (eq. 6 convention).

    Returns
    -------
    ndarray, shape (..., 3)
        f [N], base frame.
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        return _motor_load_gu(_f8(jacobian), _f8(tau_m))


def load_hessian(jacobian: npt.ArrayLike, force: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Load Hessian H = d(U^T f)/dq at constant f, H_ab = z_a . (u_b x f) for a <= b.

    ``H = d^2 (f . p_e)/dq^2`` is the geometric stiffness of the load (the derivative of eq. 5
    of 000_ce37cf035a0a87c6 in q): the equilibrium of eq. (7) is stable where K - H_kk is
    positive definite (``equilibrium_stiffness``, ``stable``).

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian: linear rows U (columns u_b) and joint axes z_a.
    force : array-like, shape (..., 3)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (..., 7, 7)
        Symmetric H [N·m/rad], DH order.
    """
    return _load_hessian_gu(_f8(jacobian), _f8(force))


def equilibrium_stiffness(
    hessian: npt.ArrayLike, stiffness: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """K - H_kk: the derivative of the residual of eq. (7) in q_k at constant f.

    Parameters
    ----------
    hessian : array-like, shape (..., 7, 7)
        Load Hessian (``load_hessian``).
    stiffness : array-like, shape (4,)
        k [N·m/rad].

    Returns
    -------
    ndarray, shape (..., 4, 4)
        [N·m/rad]; the equilibrium is stable where it is positive definite.
    """
    return _equilibrium_stiffness_gu(_f8(hessian), _f8(stiffness))


def stable(hessian: npt.ArrayLike, stiffness: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether K - H_kk is positive definite (a stable equilibrium), shape (...)."""
    return _stable_gu(_f8(hessian), _f8(stiffness))


def reduced_newton_matrix(
    jacobian: npt.ArrayLike, hessian: npt.ArrayLike, stiffness: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """D = K - H_kk + U_k^T U_m^-T H_mk, the derivative of the reduced residual of Fig. 5.

    With f(q_k) = U_m^-T tau_m eliminated by eq. (6), the reduced residual of eq. (7) is
    g(q_k) = K q_k - U_k^T f(q_k), and dg/dq_k = D (000_ce37cf035a0a87c6, section 2.3).
    sign(det U_m det D) is the sign of det(d tau_m / d f) at a stable equilibrium: D is singular
    on the folds of the map f -> tau_m, where two estimates meet.

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian at the configuration.
    hessian : array-like, shape (..., 7, 7)
        Load Hessian at that configuration and the force f(q_k).
    stiffness : array-like, shape (4,)
        k [N·m/rad].

    Returns
    -------
    ndarray, shape (..., 4, 4)
        D [N·m/rad].
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        return _reduced_newton_matrix_gu(_f8(jacobian), _f8(hessian), _f8(stiffness))


def conditioning(
    jacobian: npt.ArrayLike, force: npt.ArrayLike, stiffness: npt.ArrayLike
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """How well motor torques determine a solution of eqs (6)-(7), and where it folds.

    Parameters
    ----------
    jacobian : array-like, shape (..., 6, 7)
        Tip Jacobian at the solution (finite).
    force : array-like, shape (..., 3)
        The solution's tip force f [N].
    stiffness : array-like, shape (4,)
        k [N·m/rad].

    Returns
    -------
    condition : ndarray, shape (...)
        2-norm condition number of U_m (inf where singular or not finite): the amplification
        of relative torque errors into the force of eq. (6).
    sigma : ndarray, shape (...)
        Smallest singular value of D (``reduced_newton_matrix``) [N·m/rad]: zero on a fold of
        f -> tau_m, where two solutions meet; NaN where D is not finite.
    direction : ndarray, shape (..., 4)
        Its right singular vector (unit, q_k space; zero where D is not finite): along it the
        solutions of a fold meet.
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        return _conditioning_gu(_f8(jacobian), _f8(force), _f8(stiffness))


# --- arm-level forms -------------------------------------------------------------------------


def _q_and_force(arm: object, q: npt.ArrayLike, force: npt.ArrayLike):
    check_arm(arm)
    return _broadcast(check_batch('q', q, 7, 'rad'), check_batch('force', force, 3, 'N'))


def motor_torques(arm: object, q: npt.ArrayLike, force: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Motor torques that hold a tip force, tau_m = U_m(q)^T f, eq. (6) of 000_....

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (..., 7)
        Joint angles [rad], DH order, spring deflections included (at equilibrium for a
        physically consistent state).
    force : array-like, shape (..., 3)
        Tip force f [N], base frame (broadcast against ``q``).

    Returns
    -------
    ndarray, shape (..., 3)
        tau_m [N·m] on DH joints 1, 2, 5: the load torque about each motor axis (the motor
        applies ``-tau_m``).

    Raises
    ------
    ValueError
        If an argument has the wrong shape or is not finite.
    """
    q, f = _q_and_force(arm, q, force)
    return load_torques(tip_position_and_jacobian(arm, q)[1], f)[..., _M]


def spring_torques(
    arm: object, q: npt.ArrayLike, force: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Load torques on the springs, U_k(q)^T f (eq. 5 restricted to DH joints 3, 4, 6, 7).

    At equilibrium they equal k q_k (eq. 7).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (..., 7)
        Joint angles [rad], DH order.
    force : array-like, shape (..., 3)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (..., 4)
        Spring load torques [N·m].

    Raises
    ------
    ValueError
        If an argument has the wrong shape or is not finite.
    """
    q, f = _q_and_force(arm, q, force)
    return load_torques(tip_position_and_jacobian(arm, q)[1], f)[..., _S]


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
    q : array-like, shape (..., 7)
        Joint angles [rad], DH order, spring deflections included.
    force : array-like, shape (..., 3)
        Tip force f [N], base frame.

    Returns
    -------
    ndarray, shape (..., 2)
        Moments [N·m] on link 1 (springs DH 3, 4) and link 2 (springs DH 6, 7).

    Raises
    ------
    ValueError
        If an argument has the wrong shape or is not finite.
    """
    t = spring_torques(arm, q, force)
    return np.stack([np.hypot(t[..., 0], t[..., 1]), np.hypot(t[..., 2], t[..., 3])], axis=-1)


# --- the solvers -----------------------------------------------------------------------------

STATUS_NAMES = ('converged', 'max_iterations', 'line_search', 'diverged', 'unstable',
                'out_of_range')
_STATUS_ARRAY = np.array(STATUS_NAMES)
_CONVERGED, _MAX_ITERATIONS, _LINE_SEARCH, _DIVERGED, _UNSTABLE, _OUT_OF_RANGE = range(6)
_NEWTON, _FIXED_POINT, _CONTINUATION = range(3)


@dataclass(frozen=True)
class ElastostaticSolution:
    """A spring equilibrium of eq. (7): the deflections and the load that they hold.

    The result of every solver here, forward (``spring_deflections``: the force is given) and
    inverse (``solve_load_*``: the force is solved from the motor torques). ``batch`` below is
    the broadcast leading shape of the inputs; for a single configuration it is () and the
    per-sample fields are Python scalars.

    Attributes
    ----------
    force : ndarray, shape batch + (3,)
        Tip force f [N], base frame; NaN where not converged.
    q_k : ndarray, shape batch + (4,)
        Spring deflections [rad], DH joints 3, 4, 6, 7; NaN where not converged.
    tau_k : ndarray, shape batch + (4,)
        Spring torques k q_k [N·m] (eq. 7); NaN where not converged.
    tip_position : ndarray, shape batch + (3,)
        Deflected tip position [m], base frame; NaN where not converged.
    jacobian : ndarray, shape batch + (6, 7)
        Tip Jacobian (eq. 4) at the equilibrium; NaN where not converged.
    iterations : int or ndarray of int, shape batch
        Newton (or fixed-point) steps taken.
    residual : float or ndarray, shape batch
        max |k q_k - U_k^T f| [N·m] at the last iterate.
    status : str or ndarray of str, shape batch
        One of ``STATUS_NAMES``: ``'converged'``; ``'max_iterations'``; ``'line_search'`` (no
        step reduced the residual, or a singular Newton matrix); ``'diverged'`` (iterates
        beyond twice the model range, or not finite, e.g. where U_m is singular);
        ``'unstable'`` (K - H_kk not positive definite); ``'out_of_range'`` (an equilibrium
        with some |q_k| > SPRING_DEFLECTION_LIMIT, outside the model).
    """

    force: npt.NDArray[np.float64]
    q_k: npt.NDArray[np.float64]
    tau_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    jacobian: npt.NDArray[np.float64]
    iterations: int | npt.NDArray[np.int64]
    residual: float | npt.NDArray[np.float64]
    status: str | npt.NDArray[np.str_]

    @property
    def converged(self) -> bool | npt.NDArray[np.bool_]:
        """Where ``status`` is ``'converged'``."""
        return self.status == 'converged'


@njit(**_JIT)
def _evaluate(dh_table, q_m, q_k, load, inverse, k, q, pose, J, origins, f, g):
    """Kinematics, force and residual of eq. (7) at q_k; returns |g|^2 (NaN if not finite).

    ``load`` is f itself (forward problem) or tau_m, and then f = U_m^-T tau_m (inverse).
    """
    for i in range(3):
        q[_M[i]] = q_m[i]
    for i in range(4):
        q[_S[i]] = q_k[i]
    dh_chain_kinematics(dh_table, q, pose, J, origins)
    if inverse:
        _motor_load(J, load, f)
    else:
        f[:] = load
    _spring_residual(J, f, q_k, k, g)
    merit = 0.0
    for i in range(4):
        merit += g[i] * g[i]
    return merit if math.isfinite(merit) else math.nan


@njit(**_JIT)
def _solve_sample(dh_table, q_m, load, inverse, fixed_point, k, q_k0, tol, max_iterations,
                  q_k_out, f_out, tip_out, J_out):
    """Newton's method (or the fixed point of Fig. 5) on the residual of eq. (7), one sample.

    Newton uses K - H_kk (forward) or D (inverse, ``reduced_newton_matrix``), a correction
    shortened to MAX_NEWTON_STEP and a backtracking (Armijo) line search on |g|^2. Returns
    (status code, iterations, residual); the outputs hold the last iterate.
    """
    q, origins = np.empty(7), np.empty((8, 3))
    pose, J, f, g = np.empty((4, 4)), np.empty((6, 7)), np.empty(3), np.empty(4)
    pose_t, J_t, f_t, g_t = np.empty((4, 4)), np.empty((6, 7)), np.empty(3), np.empty(4)
    H, A, d = np.empty((7, 7)), np.empty((4, 4)), np.empty(4)
    x = q_k0.copy()
    merit = _evaluate(dh_table, q_m, x, load, inverse, k, q, pose, J, origins, f, g)
    iterations = 0
    status = _MAX_ITERATIONS
    residual = math.inf
    while True:
        residual = max(abs(g[0]), abs(g[1]), abs(g[2]), abs(g[3]))
        if not math.isfinite(merit):
            status = _DIVERGED
            break
        if residual <= tol:
            status = _CONVERGED
            break
        if iterations >= max_iterations:
            break
        iterations += 1
        if fixed_point:  # Fig. 5: q_k <- U_k^T f / k
            for i in range(4):
                x[i] -= g[i] / k[i]
            merit = _evaluate(dh_table, q_m, x, load, inverse, k, q, pose, J, origins, f, g)
        else:
            _load_hessian(J, f, H)
            if inverse:
                _reduced_newton_matrix(J, H, k, A)
            else:
                _equilibrium_stiffness(H, k, A)
            if not _solve4(A, -g, d):
                status = _LINE_SEARCH
                break
            size = max(abs(d[0]), abs(d[1]), abs(d[2]), abs(d[3]))
            if not math.isfinite(size):
                status = _LINE_SEARCH
                break
            if size > MAX_NEWTON_STEP:
                d *= MAX_NEWTON_STEP / size
            alpha = 1.0
            accepted = False
            for _ in range(_MAX_HALVINGS):
                trial = x + alpha * d
                merit_t = _evaluate(dh_table, q_m, trial, load, inverse, k, q, pose_t, J_t,
                                    origins, f_t, g_t)
                if merit_t <= (1.0 - 2.0 * _ARMIJO * alpha) * merit:
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted:
                status = _LINE_SEARCH
                break
            x, merit = trial, merit_t
            pose, pose_t, J, J_t, f, f_t, g, g_t = pose_t, pose, J_t, J, f_t, f, g_t, g
        if max(abs(x[0]), abs(x[1]), abs(x[2]), abs(x[3])) > _DIVERGED:
            status = _DIVERGED
            break
    if status == _CONVERGED:
        if max(abs(x[0]), abs(x[1]), abs(x[2]), abs(x[3])) > SPRING_DEFLECTION_LIMIT:
            status = _OUT_OF_RANGE
        else:
            _load_hessian(J, f, H)
            _equilibrium_stiffness(H, k, A)
            if not _positive_definite(A):
                status = _UNSTABLE
    q_k_out[:] = x
    f_out[:] = f
    tip_out[:] = pose[:3, 3]
    J_out[:, :] = J
    return status, iterations, residual


@njit(**_JIT)
def newton_load_sample(dh_table, q_m, tau_m, k, q_k0, tol, max_iterations, q_k_out, f_out,
                       tip_out, J_out):
    """``solve_load_newton`` of one sample, for compiled callers (a numba kernel).

    Parameters
    ----------
    dh_table : ndarray
        ``FlexibleArm.dh_table``.
    q_m, tau_m : ndarray, shape (3,)
        Finite motor angles [rad] and torques [N·m] (eq. 6 convention); the caller checked them.
    k : ndarray, shape (4,)
        Stiffness [N·m/rad] (``check_stiffness``).
    q_k0 : ndarray, shape (4,)
        Start [rad].
    tol : float
        Residual tolerance [N·m].
    max_iterations : int
        Newton steps allowed.
    q_k_out, f_out, tip_out, J_out : ndarray, shapes (4,), (3,), (3,), (6, 7)
        Outputs: the last iterate, its force, tip and Jacobian.

    Returns
    -------
    status, iterations, residual
        Status code (index of ``STATUS_NAMES``; 0 is converged), Newton steps, residual [N·m].
    """
    return _solve_sample(dh_table, q_m, tau_m, True, False, k, q_k0, tol, max_iterations,
                         q_k_out, f_out, tip_out, J_out)


@njit(**_JIT)
def _continue_sample(dh_table, q_m, tau_m, k, steps, tol, max_iterations, q_k_out, f_out,
                     tip_out, J_out):
    """Continuation in the torques: lambda tau_m from 0 to 1, each solved from the last."""
    x = np.zeros(4)
    lam, step = 0.0, 1.0 / steps
    total = 0
    while True:
        target = min(1.0, lam + step)
        status, iterations, residual = _solve_sample(
            dh_table, q_m, target * tau_m, True, False, k, x, tol, max_iterations, q_k_out,
            f_out, tip_out, J_out)
        total += iterations
        if status == _CONVERGED:
            lam = target
            x[:] = q_k_out
        else:
            step *= 0.5
        if lam >= 1.0 or step < 1.0 / (8 * steps):
            return status, total, residual


@njit(**_JIT)
def _solve_rows(dh_table, Q_m, loads, inverse, mode, k, Q_k0, tol, max_iterations, steps,
                Q_k, F, tips, Js, status, iterations, residual):
    for i in range(Q_m.shape[0]):
        if mode == _CONTINUATION:
            status[i], iterations[i], residual[i] = _continue_sample(
                dh_table, Q_m[i], loads[i], k, steps, tol, max_iterations, Q_k[i], F[i],
                tips[i], Js[i])
        else:
            status[i], iterations[i], residual[i] = _solve_sample(
                dh_table, Q_m[i], loads[i], inverse, mode == _FIXED_POINT, k, Q_k0[i], tol,
                max_iterations, Q_k[i], F[i], tips[i], Js[i])


def _rows(x: npt.NDArray[np.float64], batch: tuple[int, ...], n: int):
    """``x`` (batch + (n,), or broadcastable to it) as C-contiguous writable rows (N, n).

    Always the same array type, so that the compiled solver has a single specialization.
    """
    if x.shape[:-1] != batch:
        x = np.broadcast_to(x, batch + (n,))
    return np.require(x.reshape(-1, n), np.float64, ['C', 'W'])


def _run(arm, q_m, load, load_name, load_unit, stiffness, q_k0, tol, max_iterations, *,
         inverse, mode=_NEWTON, steps=1) -> ElastostaticSolution:
    """Validate, broadcast, solve every sample in compiled code, shape the result."""
    check_arm(arm)
    q_m = check_batch('q_m', q_m, 3, 'rad')
    load = check_batch(load_name, load, 3, load_unit)
    if q_m.shape != load.shape:
        q_m, load = _broadcast(q_m, load)
    k = np.require(check_stiffness(stiffness), np.float64, ['C', 'W'])
    tol, max_iterations = check_solver_options(tol, max_iterations)
    batch = q_m.shape[:-1]
    Q_m, loads = _rows(q_m, batch, 3), _rows(load, batch, 3)
    N = len(Q_m)
    Q_k0 = np.zeros((N, 4)) if q_k0 is None else _rows(check_batch('q_k0', q_k0, 4, 'rad'),
                                                         batch, 4)
    return _solve_and_shape(arm.dh_table, Q_m, loads, k, Q_k0, tol, max_iterations, inverse,
                            mode, steps, batch)


def _solve_and_shape(dh_table, Q_m, loads, k, Q_k0, tol, max_iterations, inverse, mode, steps,
                     batch) -> ElastostaticSolution:
    """Solve the checked rows (N, .) in compiled code and shape the result as ``batch``."""
    N = len(Q_m)
    Q_k, F, tips, Js = np.empty((N, 4)), np.empty((N, 3)), np.empty((N, 3)), np.empty((N, 6, 7))
    counts, residual = np.empty((2, N), np.int64), np.empty(N)
    _solve_rows(dh_table, Q_m, loads, inverse, mode, k, Q_k0, tol, max_iterations, steps,
                Q_k, F, tips, Js, counts[0], counts[1], residual)
    codes, iterations = counts
    if batch == ():
        if codes[0] != _CONVERGED:
            Q_k[0], F[0], tips[0], Js[0] = np.nan, np.nan, np.nan, np.nan
        return ElastostaticSolution(F[0], Q_k[0], k * Q_k[0], tips[0], Js[0],
                                    int(iterations[0]), float(residual[0]),
                                    STATUS_NAMES[codes[0]])
    bad = codes != _CONVERGED
    if bad.any():
        for array in (Q_k, F, tips, Js):
            array[bad] = np.nan
    return ElastostaticSolution(
        F.reshape(batch + (3,)), Q_k.reshape(batch + (4,)), (k * Q_k).reshape(batch + (4,)),
        tips.reshape(batch + (3,)), Js.reshape(batch + (6, 7)), iterations.reshape(batch),
        residual.reshape(batch), _STATUS_ARRAY[codes].reshape(batch))


def spring_deflections(
    arm: object,
    q_m: npt.ArrayLike,
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    q_k0: npt.ArrayLike | None = None,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> ElastostaticSolution:
    """Spring deflections of the arm holding a tip force, eqs (5)-(7) of 000_ce37cf035a0a87c6.

    Solves the equilibrium ``k q_k = U_k(q_m, q_k)^T f`` (nonlinear in q_k through the
    Jacobian) by Newton's method with the matrix K - H_kk and a backtracking line search; the
    equilibrium found must be stable and within the model range.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_m : array-like, shape (..., 3)
        Motor angles [rad], DH joints 1, 2, 5.
    force : array-like, shape (..., 3)
        Tip force f [N], base frame (broadcast against ``q_m``).
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or per spring (see ``check_stiffness``).
    q_k0 : array-like, shape (..., 4), optional
        Initial guess [rad] (warm start); zeros by default.
    tol : float, optional
        Residual tolerance max |k q_k - U_k^T f| [N·m], positive.
    max_iterations : int, optional
        Newton iterations allowed, >= 1.

    Returns
    -------
    ElastostaticSolution
        NaN where ``converged`` is False.

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values, non-positive stiffness or
        tolerances.
    """
    return _run(arm, q_m, force, 'force', 'N', stiffness, q_k0, tol, max_iterations,
                inverse=False)


def solve_load_fixed_point(
    arm: object,
    q_m: npt.ArrayLike,
    tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    q_k0: npt.ArrayLike | None = None,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> ElastostaticSolution:
    """Load and deflections from motor torques by the fixed point of Fig. 5 of 000_....

    Iterates f = U_m^-T tau_m (eq. 6), q_k = U_k^T f / k (eq. 7) from q_k0 until the residual
    of eq. (7) is below ``tol``. It contracts only while the load's geometric stiffness stays
    small against k (the package README gives measured failure rates); ``solve_load_newton``
    does not need that. Parameters, result and errors as ``solve_load_newton``'s
    (``max_iterations``: iterations of the fixed point).
    """
    return _run(arm, q_m, tau_m, 'tau_m', 'N·m', stiffness, q_k0, tol, max_iterations,
                inverse=True, mode=_FIXED_POINT)


def solve_load_newton(
    arm: object,
    q_m: npt.ArrayLike,
    tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    q_k0: npt.ArrayLike | None = None,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> ElastostaticSolution:
    """Load and deflections from motor torques by Newton's method on the reduced residual.

    With f(q_k) = U_m^-T tau_m (eq. 6 of 000_ce37cf035a0a87c6) eliminated, solves
    g(q_k) = K q_k - U_k^T f(q_k) = 0 (eq. 7) with the derivative D of
    ``reduced_newton_matrix`` and a backtracking line search on |g|^2, from q_k0.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_m : array-like, shape (..., 3)
        Motor angles [rad], DH joints 1, 2, 5.
    tau_m : array-like, shape (..., 3)
        Motor torques [N·m] (eq. 6 convention), broadcast against ``q_m``.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or per spring (see ``check_stiffness``).
    q_k0 : array-like, shape (..., 4), optional
        Start [rad] (a warm start); zeros (the rigid arm) by default.
    tol : float, optional
        Residual tolerance [N·m], positive.
    max_iterations : int, optional
        Newton iterations allowed, >= 1.

    Returns
    -------
    ElastostaticSolution

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values, non-positive stiffness or
        tolerances.
    """
    return _run(arm, q_m, tau_m, 'tau_m', 'N·m', stiffness, q_k0, tol, max_iterations,
                inverse=True)


def solve_load_continuation(
    arm: object,
    q_m: npt.ArrayLike,
    tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    steps: int = 8,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> ElastostaticSolution:
    """Load and deflections from motor torques by continuation from the unloaded arm.

    Follows the solution of ``solve_load_newton`` while the torques grow from 0 to tau_m:
    lambda tau_m for lambda = 1/steps, 2/steps, ..., 1, each solved from the previous
    solution, an increment that fails halved (down to 1/(8 steps)). It finds the branch of the
    unloaded arm where a direct Newton solve from q_k = 0 fails.

    Parameters, result and errors as ``solve_load_newton``'s, with no ``q_k0`` and:

    Parameters
    ----------
    steps : int, optional
        Increments of lambda, >= 1 (``ValueError`` otherwise).
    max_iterations : int, optional
        Newton iterations allowed per increment, >= 1; ``iterations`` in the result is
        their sum over the increments.
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f'expected steps an integer >= 1, got {steps!r}')
    return _run(arm, q_m, tau_m, 'tau_m', 'N·m', stiffness, None, tol, max_iterations,
                inverse=True, mode=_CONTINUATION, steps=int(steps))



def warm_up(arm: object | None = None) -> None:
    """Compile every kernel of this module, or load it from numba's on-disk cache.

    The kernels compile on their first call (about a minute on a 2-core machine, once per
    source change; later processes load them from the cache in ``__pycache__`` in well under
    a second). Call this where a first call must not be slow: at set-up, or before a node
    starts its timers.

    Parameters
    ----------
    arm : FlexibleArm, optional
        The arm to solve for; a default ``FlexibleArm`` if None.
    """
    if arm is None:
        from inflarm_model.kinematics import FlexibleArm  # noqa: PLC0415 (only when needed)

        arm = FlexibleArm()
    q_m, force = np.array([0.3, 0.8, -1.2]), np.array([0.0, 10.0, -15.0])
    equilibrium = spring_deflections(arm, q_m, force, DEFAULT_STIFFNESS)
    q = np.empty(7)
    q[list(_M)], q[list(_S)] = q_m, equilibrium.q_k
    tau_m = motor_torques(arm, q, force)
    for solver in (solve_load_newton, solve_load_fixed_point, solve_load_continuation):
        solver(arm, q_m, tau_m, DEFAULT_STIFFNESS)
    J = equilibrium.jacobian
    conditioning(J, force, np.full(4, DEFAULT_STIFFNESS))
    H = load_hessian(J, force)
    reduced_newton_matrix(J, H, np.full(4, DEFAULT_STIFFNESS))


if __name__ == '__main__':
    warm_up()
