"""Elastostatic inverse kinematics of the inflatable-link arm (section 2.4, Fig. 6, eqs 8-9).

With the tip load f (known, constant) and the spring stiffness k, the motor angles q_m are
chosen so that the *deflected* tip, q_k solved from the equilibrium k q_k = U_k^T f
(``inflarm_model.elastostatics``, same sign convention), reaches the target. Pure numpy and
Pinocchio, no ROS.

Velocity map. Only the tip position is controlled and a pure force meets only the linear rows
U (3x7) of the Jacobian, so the paper's right pseudo-inverse (eq. 8) is taken of U::

    U^# = U^T (U U^T)^-1                (7x3),   J_m^# = U_m^T (U U^T)^-1   (3x3)

J_m^# is the 3 motor rows of U^# (eq. 9's "motor-associated rows"). It treats the springs as
free joints sharing the motion with the motors; in fact they follow the motors through the
equilibrium, dq_k/dq_m = (K - H_kk)^-1 H_km (H: the load Hessian), so the exact map from motor
rates to tip velocity is the effective Jacobian

    J_eff = U_m + U_k (K - H_kk)^-1 H_km     (3x3).

``track_trajectory`` integrates eq. (9), dq_m/dt = J^# (v_d + K e), with either map
(``method='paper'``: J_m^#; ``'effective'``: J_eff^-1, which feeds the desired velocity
forward exactly). ``solve_ik`` reaches a point target by damped Newton steps on J_eff (quadratic
convergence, to 1e-10 m by default).

Unreachable targets (beyond the reach 2L, too close to the base, on the first joint's axis) and
singular or non-converging solves raise ValueError with the reason; no silently wrong numbers.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from inflarm_model.elastostatics import (
    MOTOR_INDICES,
    SPRING_INDICES,
    check_arm,
    check_stiffness,
    equilibrium_stiffness,
    link_moments,
    load_hessian,
    spring_deflections,
    tip_position_and_jacobian,
)
from inflarm_model.link import (
    TESTED_PRESSURES,
    lowest_sufficient_pressure,
    min_pressure_for_moment,
)
from inflarm_model.validation import check_rows, check_vector

__all__ = [
    'DEFAULT_MAX_CONDITION',
    'DEFAULT_MIN_AXIS_DISTANCE',
    'DEFAULT_MIN_REACH',
    'DEFAULT_POSITION_TOLERANCE',
    'PressureRequirement',
    'TrackingResult',
    'effective_jacobian',
    'minimum_pressure_along',
    'motor_pseudo_inverse',
    'solve_ik',
    'solve_rigid_ik',
    'straight_line_trajectory',
    'track_trajectory',
]

DEFAULT_POSITION_TOLERANCE = 1e-10  # tip position error [m]
DEFAULT_MAX_CONDITION = 1e6  # of the 3x3 tip Jacobian used for the step
# Targets closer to the base than this fold the two links onto each other (radius 55 mm) and
# approach the folded-elbow singularity [m].
DEFAULT_MIN_REACH = 0.1
# Targets this close to the first joint's axis leave the base yaw undetermined [m].
DEFAULT_MIN_AXIS_DISTANCE = 1e-3
_MAX_STEP = 0.2  # largest motor correction per Newton iteration [rad]
_MAX_HALVINGS = 20
_SPRING_TOL = 1e-11  # equilibrium residual for the inner spring solves [N·m]
_SPRING_ITERATIONS = 50


# --- validation ------------------------------------------------------------------------------


def _link_length(arm: object) -> float:
    L = getattr(arm, 'link_length', None)
    if not (isinstance(L, float) and math.isfinite(L) and L > 0.0):
        raise ValueError(f'expected an arm with a positive link_length [m], got '
                         f'{type(arm).__name__}')
    return L


def _check_target(target: npt.NDArray[np.float64], reach: float, min_reach: float,
                  min_axis_distance: float) -> None:
    """Raise ValueError naming why ``target`` cannot be reached."""
    distance = float(np.linalg.norm(target))
    if distance > reach:
        raise ValueError(f'target {target.tolist()} is beyond the reach of the arm: '
                         f'|target| = {distance:.6g} m > 2L = {reach:.6g} m')
    if distance < min_reach:
        raise ValueError(f'target {target.tolist()} is too close to the base: |target| = '
                         f'{distance:.6g} m < min_reach = {min_reach:.6g} m (folded links, '
                         'singular elbow)')
    if math.hypot(target[0], target[1]) < min_axis_distance:
        raise ValueError(f'target {target.tolist()} is on the first joint axis (within '
                         f'{min_axis_distance:.3g} m): singular, the base yaw is undetermined')


# --- rigid arm (Table 1) ---------------------------------------------------------------------


def _rigid_candidates(target: npt.NDArray[np.float64], L: float) -> list[tuple[float, ...]]:
    """The (up to) four closed-form solutions of Table 1: shoulder front/back x elbow up/down.

    Tip of Table 1: (r cos q1, r sin q1, z), r = L cos q2 + L cos(q2 + q3),
    z = L sin q2 + L sin(q2 + q3).
    """
    x, y, z = target.tolist()
    rho = math.hypot(x, y)
    yaw = math.atan2(y, x)
    out = []
    for q1, r in ((yaw, rho), (yaw + math.pi, -rho)):
        c3 = max(-1.0, min(1.0, (r * r + z * z - 2.0 * L * L) / (2.0 * L * L)))
        for q3 in (math.acos(c3), -math.acos(c3)):
            q2 = math.atan2(z, r) - math.atan2(math.sin(q3), 1.0 + math.cos(q3))
            out.append((q1, q2, q3))
    return out


def _nearest(candidates: Sequence[tuple[float, ...]], q0: npt.NDArray[np.float64]):
    """The candidate closest to q0 (angles wrapped), unwrapped next to q0."""
    best, best_d = None, math.inf
    for c in candidates:
        c = np.asarray(c)
        c = c + 2.0 * math.pi * np.round((q0 - c) / (2.0 * math.pi))
        d = float(np.abs(c - q0).max())
        if d < best_d:
            best, best_d = c, d
    return best


def solve_rigid_ik(
    rigid_arm: object,
    target: npt.ArrayLike,
    q_m0: npt.ArrayLike,
    *,
    min_reach: float = DEFAULT_MIN_REACH,
    min_axis_distance: float = DEFAULT_MIN_AXIS_DISTANCE,
) -> npt.NDArray[np.float64]:
    """Rigid-arm inverse kinematics (Table 1 of 000_ce37cf035a0a87c6), the baseline of Fig. 11.

    Closed form: of the four solutions (shoulder front/back, elbow up/down) the one nearest
    ``q_m0`` is returned, unwrapped next to it (continuous along a trajectory).

    Parameters
    ----------
    rigid_arm : RigidArm
        The 3-DOF rigid arm (two links of length ``link_length``).
    target : array-like, shape (3,)
        Tip position [m], base frame.
    q_m0 : array-like, shape (3,)
        Reference motor angles [rad] picking the branch.
    min_reach, min_axis_distance : float, optional
        See ``solve_ik``.

    Returns
    -------
    ndarray, shape (3,)
        Motor angles [rad] putting the rigid tip on ``target``.

    Raises
    ------
    ValueError
        On invalid arguments or a target beyond 2L, closer than ``min_reach`` or on the first
        joint's axis.
    """
    L = _link_length(rigid_arm)
    x = check_vector('target', target, 3, 'm')
    q0 = check_vector('q_m0', q_m0, 3, 'rad')
    _check_target(x, 2.0 * L, min_reach, min_axis_distance)
    return _nearest(_rigid_candidates(x, L), q0)


# --- the flexible arm ------------------------------------------------------------------------


_M, _S = list(MOTOR_INDICES), list(SPRING_INDICES)


def _effective(J, f, k):
    """J_eff = U_m + U_k (K - H_kk)^-1 H_km from the tip Jacobian J (6, 7)."""
    H = load_hessian(J, f)
    follow = np.linalg.solve(equilibrium_stiffness(H, k), H[np.ix_(_S, _M)])  # dq_k/dq_m
    return J[:3, _M] + J[:3, _S] @ follow


def effective_jacobian(
    arm: object, q: npt.ArrayLike, force: npt.ArrayLike, stiffness: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Tip velocity per motor rate with the springs in equilibrium, J_eff (3x3).

    ``J_eff = U_m + U_k (K - H_kk)^-1 H_km``: the motors move the tip directly (U_m) and
    through the deflections they induce, dq_k/dq_m = (K - H_kk)^-1 H_km (derivative of
    k q_k = U_k^T f at constant f, eq. 7 of 000_ce37cf035a0a87c6; H from
    ``inflarm_model.elastostatics.load_hessian``).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,)
        Joint angles [rad], DH order, at equilibrium.
    force : array-like, shape (3,)
        Tip force [N], base frame.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].

    Returns
    -------
    ndarray, shape (3, 3)
        d p_e / d q_m [m/rad], base frame.

    Raises
    ------
    ValueError
        On invalid arguments.
    """
    q = check_vector('q', q, 7, 'rad')
    f = check_vector('force', force, 3, 'N')
    k = check_stiffness(stiffness)
    return _effective(tip_position_and_jacobian(arm, q)[1], f, k)


def _paper_inverse(J):
    """J_m^# = U_m^T (U U^T)^-1, the motor rows of the right pseudo-inverse of U (eq. 8)."""
    U = J[:3]
    return U[:, _M].T @ np.linalg.inv(U @ U.T)


def motor_pseudo_inverse(arm: object, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Motor rows of the right pseudo-inverse of the linear Jacobian, eqs (8)-(9).

    ``J_m^# = U_m^T (U U^T)^-1`` with U the 3x7 linear block of the Jacobian of eq. (4): the
    motor rows of U^# = U^T (U U^T)^-1, the position-only form of eq. (8).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q : array-like, shape (7,)
        Joint angles [rad], DH order.

    Returns
    -------
    ndarray, shape (3, 3)
        Motor rates per tip velocity [rad/m].

    Raises
    ------
    ValueError
        On invalid arguments.
    """
    return _paper_inverse(tip_position_and_jacobian(arm, check_vector('q', q, 7, 'rad'))[1])


def _hadamard_ratio(A: npt.NDArray[np.float64]) -> float:
    """|det A| over the product of its row norms, in [0, 1]: a scale-free singularity measure
    (at least 1/cond^2)."""
    norms = float(np.prod(np.linalg.norm(A, axis=1)))
    return abs(float(np.linalg.det(A))) / norms if norms > 0.0 else 0.0


# Below this Hadamard ratio of the 3x3 map track_trajectory treats the configuration as
# singular.
_MIN_RATIO = 1e-9


class _Springs:
    """Warm-started spring equilibria of one arm under a constant load."""

    def __init__(self, arm: object, force: npt.NDArray[np.float64], k: npt.NDArray[np.float64]):
        check_arm(arm)
        self.arm, self.f, self.k = arm, force, k
        self.q_k = np.zeros(4)

    def solve(self, q_m: npt.NDArray[np.float64]):
        """Equilibrium at these motor angles: ``(q (7,), Jacobian (6, 7), tip (3,))``.

        Raises ValueError when it fails.
        """
        eq = spring_deflections(self.arm, q_m, self.f, self.k, q_k0=self.q_k, tol=_SPRING_TOL,
                                max_iterations=_SPRING_ITERATIONS)
        if not eq.converged:
            raise ValueError(f'spring equilibrium at q_m = {q_m.tolist()} failed ({eq.status}, '
                             f'residual {eq.residual:.3g} N·m after {eq.iterations} iterations)')
        self.q_k = eq.q_k
        q = np.empty(7)
        q[_M], q[_S] = q_m, eq.q_k
        return q, eq.jacobian, eq.tip_position


def solve_ik(
    arm: object,
    target: npt.ArrayLike,
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    q_m0: npt.ArrayLike,
    *,
    tol: float = DEFAULT_POSITION_TOLERANCE,
    max_iterations: int = 50,
    max_condition: float = DEFAULT_MAX_CONDITION,
    min_reach: float = DEFAULT_MIN_REACH,
    min_axis_distance: float = DEFAULT_MIN_AXIS_DISTANCE,
) -> npt.NDArray[np.float64]:
    """Motor angles whose deflected tip reaches ``target`` under the load, section 2.4.

    Starts from the rigid solution (Table 1 geometry, the branch nearest ``q_m0``), or from
    ``q_m0`` itself when its deflected tip is closer, and takes damped Newton steps
    dq_m = J_eff^-1 (target - p_e), re-solving the spring equilibrium of eq. (7) at every
    iterate (warm-started), until the deflected tip is within ``tol``.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    target : array-like, shape (3,)
        Desired tip position x_d [m], base frame.
    force : array-like, shape (3,)
        Tip force f_e [N], base frame, known and constant.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or per spring.
    q_m0 : array-like, shape (3,)
        Start / reference motor angles [rad] picking the branch (shoulder, elbow).
    tol : float, optional
        Tip position tolerance [m], positive.
    max_iterations : int, optional
        Newton iterations allowed.
    max_condition : float, optional
        Largest accepted condition number of J_eff; above it the configuration is singular.
    min_reach : float, optional
        Smallest accepted |target| [m].
    min_axis_distance : float, optional
        Smallest accepted distance of the target from the first joint's axis [m].

    Returns
    -------
    ndarray, shape (3,)
        Motor angles q_m [rad], DH joints 1, 2, 5.

    Raises
    ------
    ValueError
        On invalid arguments; a target beyond 2L, closer than ``min_reach`` or on the first
        joint's axis; a singular configuration (condition number of J_eff over
        ``max_condition``); a spring equilibrium that fails; or no convergence (the target is
        then outside the workspace of the deflected arm).
    """
    L = _link_length(arm)
    x_d = check_vector('target', target, 3, 'm')
    f = check_vector('force', force, 3, 'N')
    k = check_stiffness(stiffness)
    q0 = check_vector('q_m0', q_m0, 3, 'rad')
    tol = float(tol)
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f'expected tol positive and finite [m], got {tol!r}')
    _check_target(x_d, 2.0 * L, min_reach, min_axis_distance)
    springs = _Springs(arm, f, k)

    # Start from the rigid solution nearest q_m0, or from q_m0 itself when its deflected tip
    # is closer (a warm start along a trajectory).
    best = None
    for start in (_nearest(_rigid_candidates(x_d, L), q0), q0):
        _, J, tip = springs.solve(start)
        error = x_d - tip
        norm = float(np.linalg.norm(error))
        if best is None or norm < best[-1]:
            best = (start, J, error, norm)
    q_m, J, error, norm = best
    iterations = 0
    while norm > tol and iterations < max_iterations:
        iterations += 1
        J_eff = _effective(J, f, k)
        cond = float(np.linalg.cond(J_eff))
        if not cond <= max_condition:
            raise ValueError(f'singular configuration at q_m = {q_m.tolist()}: condition '
                             f'number of J_eff {cond:.3g} > max_condition {max_condition:.3g}')
        d = np.linalg.solve(J_eff, error)
        size = float(np.abs(d).max())
        if size > _MAX_STEP:
            d *= _MAX_STEP / size
        alpha = 1.0
        for _ in range(_MAX_HALVINGS):
            trial = q_m + alpha * d
            _, J_t, tip = springs.solve(trial)
            error_t = x_d - tip
            norm_t = float(np.linalg.norm(error_t))
            if norm_t < (1.0 - 1e-4 * alpha) * norm:
                break
            alpha *= 0.5
        else:
            break
        q_m, J, error, norm = trial, J_t, error_t, norm_t
    if norm <= tol:
        return q_m
    raise ValueError(f'elastostatic IK did not reach target {x_d.tolist()}: tip error '
                     f'{norm:.3g} m after {iterations} iterations; the target is likely '
                     'outside the workspace of the deflected arm')


# --- trajectories ----------------------------------------------------------------------------


def straight_line_trajectory(
    x_start: npt.ArrayLike, x_goal: npt.ArrayLike, duration: float, samples: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """A straight tip path with a minimum-jerk time law (zero velocity at both ends).

    ``x(t) = x_start + s(t / T) (x_goal - x_start)``, ``s(u) = 10 u^3 - 15 u^4 + 6 u^5``.

    Parameters
    ----------
    x_start, x_goal : array-like, shape (3,)
        End points [m], base frame.
    duration : float
        T [s], positive.
    samples : int
        Number of waypoints, >= 2.

    Returns
    -------
    times : ndarray, shape (samples,)
        [s], from 0 to T.
    x_d : ndarray, shape (samples, 3)
        Positions [m].
    v_d : ndarray, shape (samples, 3)
        Velocities [m/s].

    Raises
    ------
    ValueError
        On invalid arguments.
    """
    a = check_vector('x_start', x_start, 3, 'm')
    b = check_vector('x_goal', x_goal, 3, 'm')
    T = float(duration)
    if not (math.isfinite(T) and T > 0.0):
        raise ValueError(f'expected duration positive and finite [s], got {duration!r}')
    if int(samples) != samples or samples < 2:
        raise ValueError(f'expected samples an integer >= 2, got {samples!r}')
    times = np.linspace(0.0, T, int(samples))
    u = times / T
    s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
    ds = 30.0 * u**2 * (1.0 - u) ** 2 / T
    return times, a + s[:, None] * (b - a), ds[:, None] * (b - a)


@dataclass(frozen=True)
class TrackingResult:
    """Motor trajectory of the elastostatic IK along a tip trajectory (Figs 10-11).

    Attributes
    ----------
    times : ndarray, shape (N,)
        [s].
    q_m : ndarray, shape (N, 3)
        Motor angles [rad], DH joints 1, 2, 5: the set points for motor control.
    q : ndarray, shape (N, 7)
        Full joint angles [rad] at equilibrium (springs included), DH order.
    tip_position : ndarray, shape (N, 3)
        Deflected tip [m], base frame.
    tip_error : ndarray, shape (N,)
        |x_d - tip| [m].
    """

    times: npt.NDArray[np.float64]
    q_m: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    tip_error: npt.NDArray[np.float64]


def track_trajectory(
    arm: object,
    times: npt.ArrayLike,
    x_d: npt.ArrayLike,
    v_d: npt.ArrayLike,
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    q_m0: npt.ArrayLike,
    gain: npt.ArrayLike,
    *,
    method: str = 'paper',
) -> TrackingResult:
    """Integrate eq. (9), dq_m/dt = J^# (v_d + K e), along a timed tip trajectory (Fig. 6).

    At each waypoint the springs are re-solved from the equilibrium (warm-started), the
    deflected tip gives e = x_d - x_e, and an explicit Euler step to the next time stamp
    updates the motors.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    times : array-like, shape (N,)
        Strictly increasing time stamps [s], N >= 2.
    x_d : array-like, shape (N, 3)
        Desired tip positions [m], base frame.
    v_d : array-like, shape (N, 3)
        Desired tip velocities [m/s].
    force : array-like, shape (3,)
        Tip force f_e [N], base frame, constant.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].
    q_m0 : array-like, shape (3,)
        Motor angles at ``times[0]`` [rad].
    gain : float or array-like, shape (3, 3)
        K [1/s], a positive scalar or a symmetric positive definite matrix. Explicit Euler
        needs ``dt * gain`` below about 1.
    method : {'paper', 'effective'}, optional
        ``'paper'``: J^# = J_m^# = U_m^T (U U^T)^-1, the motor rows of the pseudo-inverse
        (eqs 8-9). ``'effective'``: J^# = J_eff^-1, the exact motor-to-tip map with the springs
        in equilibrium (see ``effective_jacobian``).

    Returns
    -------
    TrackingResult

    Raises
    ------
    ValueError
        On invalid arguments, a singular J^# or a failed spring equilibrium.
    """
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size < 2 or not np.isfinite(t).all() or not (np.diff(t) > 0.0).all():
        raise ValueError(f'expected times strictly increasing, finite, shape (N,) with N >= 2 '
                         f'[s], got shape {t.shape}')
    N = t.size
    X = check_rows('x_d', x_d, 3, 'm')
    V = check_rows('v_d', v_d, 3, 'm/s')
    if X.shape[0] != N or V.shape[0] != N:
        raise ValueError(f'expected x_d and v_d of shape ({N}, 3) like times, got {X.shape} '
                         f'and {V.shape}')
    f = check_vector('force', force, 3, 'N')
    k = check_stiffness(stiffness)
    q_m = check_vector('q_m0', q_m0, 3, 'rad').copy()
    K = _gain(gain)
    if method not in ('paper', 'effective'):
        raise ValueError(f"expected method 'paper' or 'effective', got {method!r}")
    springs = _Springs(arm, f, k)
    Q = np.empty((N, 7))
    tips = np.empty((N, 3))
    for n in range(N):
        Q[n], J, tips[n] = springs.solve(q_m)
        if n == N - 1:
            break
        w = V[n] + K @ (X[n] - tips[n])
        if method == 'effective':
            A = _effective(J, f, k)
            ratio = _hadamard_ratio(A)
            d = np.linalg.solve(A, w) if ratio >= _MIN_RATIO else None
        else:
            U = J[:3]
            ratio = _hadamard_ratio(U @ U.T)
            d = _paper_inverse(J) @ w if ratio >= _MIN_RATIO else None
        if d is None:
            raise ValueError(f'singular configuration at t = {t[n]:.6g} s, q_m = '
                             f'{q_m.tolist()} (Hadamard ratio {ratio:.3g})')
        q_m = q_m + (t[n + 1] - t[n]) * d
    return TrackingResult(t, Q[:, _M], Q, tips, np.linalg.norm(X - tips, axis=1))


def _gain(gain: npt.ArrayLike) -> npt.NDArray[np.float64]:
    K = np.asarray(gain, dtype=float)
    if K.shape == ():
        K = float(K) * np.eye(3)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ValueError(f'expected gain as a scalar or shape (3, 3) [1/s], got {K.shape}')
    if not np.allclose(K, K.T) or not (np.linalg.eigvalsh(K) > 0.0).all():
        raise ValueError(f'expected gain symmetric positive definite [1/s], got {K.tolist()}')
    return K


# --- wrinkling along a trajectory ------------------------------------------------------------


@dataclass(frozen=True)
class PressureRequirement:
    """Largest link moment along a trajectory and the inflation it needs (section 4).

    Attributes
    ----------
    moments : ndarray, shape (N, 2)
        Bending moment on link 1 and link 2 at each waypoint [N·m].
    max_moment : float
        Largest of them [N·m].
    link : int
        Link carrying it, 1 or 2.
    index : int
        Waypoint where it occurs.
    required_pressure : float
        Lowest pressure whose wrinkling moment (eq. 3) holds it [Pa].
    lowest_sufficient_pressure : float or None
        Lowest of the candidate (tested) pressures that holds it [Pa]; None if none does.
    """

    moments: npt.NDArray[np.float64]
    max_moment: float
    link: int
    index: int
    required_pressure: float
    lowest_sufficient_pressure: float | None


def minimum_pressure_along(
    arm: object,
    q_trajectory: npt.ArrayLike,
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    radius: float,
    pressures: npt.ArrayLike = TESTED_PRESSURES,
) -> PressureRequirement:
    """Largest link moment along a trajectory and the minimum inflation pressure, section 4.

    The moment on a link is the combination sqrt(tau_a^2 + tau_b^2) of its two orthogonal
    spring torques (``link_moments``); the pressure follows from M_w = (pi/4) pi p r^3 (eq. 3).
    The paper's simulation gives 17.51 N·m on link 1 and p >= 50 kPa among 10-60 kPa.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_trajectory : array-like, shape (N, 7) or (N, 3)
        Full joint angles at equilibrium [rad], or motor angles only, in which case the
        springs are solved from the equilibrium.
    force : array-like, shape (3,)
        Tip force [N], base frame.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].
    radius : float
        Link radius r [m].
    pressures : array-like, shape (n,), optional
        Candidate pressures [Pa]; Table 3's 10-60 kPa by default.

    Returns
    -------
    PressureRequirement

    Raises
    ------
    ValueError
        On invalid arguments or a failed spring equilibrium.
    """
    Qt = np.asarray(q_trajectory, dtype=float)
    f = check_vector('force', force, 3, 'N')
    k = check_stiffness(stiffness)
    if Qt.ndim == 2 and Qt.shape[1] == 3:
        Qm = check_rows('q_trajectory', Qt, 3, 'rad')
        springs = _Springs(arm, f, k)
        Qt = np.array([springs.solve(q_m)[0] for q_m in Qm])
    Qt = check_rows('q_trajectory', Qt, 7, 'rad')
    if Qt.shape[0] == 0:
        raise ValueError('expected a non-empty q_trajectory')
    moments = link_moments(arm, Qt, f)
    index, link = np.unravel_index(int(np.argmax(moments)), moments.shape)
    worst = float(moments[index, link])
    return PressureRequirement(
        moments, worst, int(link) + 1, int(index),
        float(min_pressure_for_moment(worst, radius)),
        lowest_sufficient_pressure(worst, radius, pressures),
    )
