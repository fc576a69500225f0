"""Load and pose estimation of the inflatable-link arm from motor torques (section 2.3).

Given the motor angles q_m and torques tau_m (DH joints 1, 2, 5) and the spring stiffness k,
find the tip force f [N] and the spring deflections q_k [rad] such that (eqs 6-7 of
000_ce37cf035a0a87c6, sign convention of ``inflarm_model.elastostatics``)::

    U_m(q)^T f = tau_m,        U_k(q)^T f = k q_k,        q = (q_m, q_k)

The equations and the solvers of Fig. 5 (fixed point, Newton on the reduced residual,
continuation) are those of ``inflarm_model.elastostatics``; this module decides what to
report.

Admissible loads. A solution is admissible when its equilibrium is stable (K - H_kk positive
definite), every |q_k| is within the model range (``SPRING_DEFLECTION_LIMIT``, pi/2) and
|f| <= ``max_force`` (default 150 N). Three motor torques do not always determine the load:
on the paper's arm 3-4 % of random configurations loaded with up to 100 N have two or three
admissible loads that give the same torques (the package README says how that was measured).

``estimate_load_and_pose`` (one sample, no history) solves by Newton from the rigid arm
(continuation if that fails) and searches for other admissible solutions by Newton from the
64 fixed starts of ``SEARCH_STARTS``. One admissible solution is returned as ``'converged'``;
two or more as ``'ambiguous'``, with every one of them in ``alternatives`` and NaN estimates.
Whether the links can carry the load is not its business: ``link_margins`` and LinkStatus
report the wrinkling margin.

``LoadTracker`` estimates a stream: it follows the solution continuous with its previous
estimate (a warm Newton start from it, which converges to the admissible solution nearest in
q_k) and reports ``'ambiguous'`` only where another admissible solution comes within reach of
the tracked one (see ``LoadTracker``), which happens where the map f -> tau_m folds.

Near-singular U_m (condition number over ``max_condition``), non-convergence and solutions
outside the admissible set are reported with NaN estimates, never as numbers.
"""

from dataclasses import dataclass
import math

from numba import njit
import numpy as np
import numpy.typing as npt
from scipy.stats import qmc

from inflarm_model.elastostatics import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_TOLERANCE,
    MOTOR_INDICES,
    SPRING_INDICES,
    check_arm,
    check_solver_options,
    check_stiffness,
    conditioning,
    conditioning_sample,
    link_moments,
    newton_load_sample,
    solve_load_continuation,
    solve_load_newton,
)
from inflarm_model.link import wrinkling_moment
from inflarm_model.validation import check_rows, check_vector

__all__ = [
    'DEFAULT_MAX_CONDITION',
    'DEFAULT_MAX_FORCE',
    'DEFAULT_MAX_ITERATIONS',
    'DEFAULT_TOLERANCE',
    'SEARCH_STARTS',
    'LoadPoseEstimate',
    'LoadPoseEstimateBatch',
    'LoadTracker',
    'estimate_load_and_pose',
    'estimate_load_and_pose_batch',
    'link_margins',
    'link_moments',
]

# Largest accepted 2-norm condition number of U_m, the 3x3 linear block of J_m.
DEFAULT_MAX_CONDITION = 1e6
# Largest admissible tip force [N]: the search for other solutions covers |f| up to here.
DEFAULT_MAX_FORCE = 150.0
# Starts of the search for other solutions: 64 points of a scrambled Sobol sequence
# (scipy.stats.qmc, seed 3) in [-1, 1]^4 rad of q_k. Measured recall in the README.
SEARCH_STARTS = 2.0 * qmc.Sobol(4, seed=3).random(64) - 1.0
SEARCH_STARTS.setflags(write=False)
_SEARCH_ITERATIONS = 30
# Two solutions closer than this in q_k [rad] are the same one.
_SAME = 1e-6
_M, _S = list(MOTOR_INDICES), list(SPRING_INDICES)

_REASONS = {
    'converged': '',
    'singular': 'U_m (linear block of J_m) is near-singular: condition number {cond:.3g} over '
                'max_condition {max_cond:.3g}; the motor torques do not determine the load',
    'ambiguous': '{n} admissible loads give these motor torques: {loads} N',
    'out_of_range': 'the only solutions found lie outside the admissible set (|f| <= '
                    '{max_force:g} N, |q_k| <= pi/2, stable): {loads} N',
    'max_iterations': 'no convergence within max_iterations={max_it} (residual {res:.3g} N·m)',
    'line_search': 'no step reduced the residual {res:.3g} N·m: no equilibrium near the '
                   'rigid estimate matches these torques',
    'diverged': 'the iterates left the model range (|q_k| > pi) or were not finite',
    'unstable': 'the equilibrium found is unstable (K - H_kk not positive definite): load '
                'beyond the stability limit of the links',
}


@dataclass(frozen=True)
class LoadPoseEstimate:
    """Estimated tip load and deflected pose (Fig. 5 of 000_ce37cf035a0a87c6).

    Attributes
    ----------
    force : ndarray, shape (3,)
        Tip force f [N], base frame. NaN unless ``converged``.
    q_k : ndarray, shape (4,)
        Spring deflections [rad], DH joints 3, 4, 6, 7. NaN unless ``converged``.
    tau_k : ndarray, shape (4,)
        Spring torques k q_k [N·m] (eq. 7). NaN unless ``converged``.
    tip_position : ndarray, shape (3,)
        Deflected tip position [m], base frame. NaN unless ``converged``.
    iterations : int
        Newton steps of the solve that gave the estimate (that of the direct solve when
        there is none).
    converged : bool
        True when the estimate is valid: the one admissible solution.
    condition_number : float
        2-norm condition number of U_m, the 3x3 linear block of J_m = [J_1 J_2 J_5], at the
        solution (at q_k = 0 when there is none).
    residual : float
        max |K q_k - U_k^T f| [N·m] of that solve.
    status : str
        ``'converged'``, ``'ambiguous'``, ``'singular'``, ``'out_of_range'`` (solutions found,
        none admissible), or the failure of the solve: ``'unstable'``, ``'max_iterations'``,
        ``'line_search'``, ``'diverged'``.
    reason : str
        Human-readable explanation; empty when converged.
    alternatives : tuple of ndarray, shape (3,) each
        With ``'ambiguous'``: every admissible load found [N], smallest first. Empty
        otherwise.
    """

    force: npt.NDArray[np.float64]
    q_k: npt.NDArray[np.float64]
    tau_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    iterations: int
    converged: bool
    condition_number: float
    residual: float
    status: str
    reason: str
    alternatives: tuple[npt.NDArray[np.float64], ...] = ()


@dataclass(frozen=True)
class LoadPoseEstimateBatch:
    """Estimates for N samples (see ``LoadPoseEstimate``; NaN rows where not converged).

    Attributes
    ----------
    force : ndarray, shape (N, 3)
        Tip forces [N], base frame.
    q_k : ndarray, shape (N, 4)
        Spring deflections [rad].
    tau_k : ndarray, shape (N, 4)
        Spring torques k q_k [N·m].
    tip_position : ndarray, shape (N, 3)
        Deflected tip positions [m], base frame.
    iterations : ndarray of int, shape (N,)
    converged : ndarray of bool, shape (N,)
    condition_number : ndarray, shape (N,)
    residual : ndarray, shape (N,)
    status : ndarray of str, shape (N,)
    reason : tuple of str, length N
    alternatives : tuple of tuples of ndarray (3,), length N
    """

    force: npt.NDArray[np.float64]
    q_k: npt.NDArray[np.float64]
    tau_k: npt.NDArray[np.float64]
    tip_position: npt.NDArray[np.float64]
    iterations: npt.NDArray[np.int64]
    converged: npt.NDArray[np.bool_]
    condition_number: npt.NDArray[np.float64]
    residual: npt.NDArray[np.float64]
    status: npt.NDArray[np.str_]
    reason: tuple[str, ...]
    alternatives: tuple[tuple[npt.NDArray[np.float64], ...], ...]

    def __len__(self) -> int:
        return len(self.force)

    def __getitem__(self, i: int) -> LoadPoseEstimate:
        """Sample i as a ``LoadPoseEstimate``."""
        return LoadPoseEstimate(
            self.force[i], self.q_k[i], self.tau_k[i], self.tip_position[i],
            int(self.iterations[i]), bool(self.converged[i]), float(self.condition_number[i]),
            float(self.residual[i]), str(self.status[i]), self.reason[i], self.alternatives[i])


# --- validation ------------------------------------------------------------------------------


def _check_options(tol, max_iterations, max_condition, max_force):
    """Validate the estimator options; return them as floats and int."""
    tol, max_iterations = check_solver_options(tol, max_iterations)
    max_condition, max_force = float(max_condition), float(max_force)
    if not max_condition >= 1.0:
        raise ValueError(f'expected max_condition >= 1, got {max_condition!r}')
    if not (math.isfinite(max_force) and max_force > 0.0):
        raise ValueError(f'expected max_force positive and finite [N], got {max_force!r}')
    return tol, max_iterations, max_condition, max_force


# --- the estimate ----------------------------------------------------------------------------


def _condition_numbers(jacobian: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """2-norm condition number of U_m for Jacobians (..., 6, 7); inf where singular or NaN."""
    out = np.full(jacobian.shape[:-2], np.inf)
    finite = np.isfinite(jacobian).all(axis=(-2, -1))
    if finite.any():
        out[finite] = conditioning(jacobian[finite], np.zeros(3), np.ones(4))[0]
    return out


def _fmt(forces) -> str:
    return ', '.join('[' + ', '.join(f'{x:.4g}' for x in f) + ']' for f in forces)


@dataclass(frozen=True)
class _Candidates:
    """The admissible solutions of each sample and the solve that found the first."""

    # per sample: (force (3,), q_k (4,), tip (3,), cond, iterations, residual) of each solution
    solutions: tuple
    main: object  # ElastostaticSolution of the direct solve, (N,)
    rejected: tuple  # per sample: forces of converged but inadmissible solutions


def _admissible(solution, max_force) -> npt.NDArray[np.bool_]:
    """Converged (stable, within the model range) with |f| <= max_force."""
    with np.errstate(invalid='ignore'):
        return solution.converged & ((solution.force**2).sum(axis=-1) <= max_force**2)


def _collect(arm, Q_m, Tau, k, starts, tol, max_iterations, max_force) -> _Candidates:
    """Direct solve (continuation where it fails) plus Newton from ``starts`` (S, 4)."""
    N = len(Q_m)
    main = solve_load_newton(arm, Q_m, Tau, k, tol=tol, max_iterations=max_iterations)
    retry = np.flatnonzero(np.isin(main.status, ('line_search', 'max_iterations', 'diverged')))
    if retry.size:
        fallback = solve_load_continuation(arm, Q_m[retry], Tau[retry], k, tol=tol,
                                           max_iterations=max_iterations)
        main = _replace_rows(main, retry, fallback)
    S = len(starts)
    parts = [main]
    if S:
        parts.append(solve_load_newton(
            arm, np.repeat(Q_m, S, axis=0), np.repeat(Tau, S, axis=0), k,
            q_k0=np.tile(starts, (N, 1)), tol=tol, max_iterations=_SEARCH_ITERATIONS))
    solutions, rejected = [], []
    keep = [_admissible(p, max_force).reshape(N, -1) for p in parts]
    converged = [np.asarray(p.converged).reshape(N, -1) for p in parts]
    forces = [p.force.reshape(N, -1, 3) for p in parts]
    q_ks = [p.q_k.reshape(N, -1, 4) for p in parts]
    tips = [p.tip_position.reshape(N, -1, 3) for p in parts]
    jacobians = [p.jacobian.reshape(N, -1, 6, 7) for p in parts]
    counts = [np.asarray(p.iterations).reshape(N, -1) for p in parts]
    residuals = [np.asarray(p.residual).reshape(N, -1) for p in parts]
    # Most starts end on the direct solution: drop those first, then compare the few left.
    first = np.where(keep[0][:, :1, None], q_ks[0][:, :1], np.inf)  # (N, 1, 4)
    for part in range(1, len(parts)):
        keep[part] &= np.abs(q_ks[part] - first).max(axis=-1) > _SAME
    for i in range(N):
        found, others = [], []
        for part in range(len(parts)):
            for j in np.flatnonzero(keep[part][i]):
                q = q_ks[part][i, j]
                if all(np.abs(q - other[1]).max() > _SAME for other in found):
                    found.append((forces[part][i, j], q, tips[part][i, j],
                                  jacobians[part][i, j], int(counts[part][i, j]),
                                  float(residuals[part][i, j])))
            for j in np.flatnonzero(converged[part][i] & ~keep[part][i]):
                f = forces[part][i, j]
                if all(np.abs(f - other).max() > 1e-6 for other in others):
                    others.append(f)
        found.sort(key=lambda s: float(np.linalg.norm(s[0])))
        solutions.append(found)
        rejected.append(tuple(others))
    # Condition numbers of the solutions kept (few), not of every start.
    kept = [s[3] for found in solutions for s in found]
    conds = iter(_condition_numbers(np.array(kept)).tolist() if kept else ())
    solutions = tuple(tuple((f, q, tip, next(conds), n, r) for f, q, tip, _, n, r in found)
                      for found in solutions)
    return _Candidates(solutions, main, tuple(rejected))


def _replace_rows(solution, rows, other):
    """``solution`` (batch (N,)) with ``rows`` taken from ``other`` (batch (len(rows),))."""
    fields = {}
    for name in ('force', 'q_k', 'tau_k', 'tip_position', 'jacobian', 'iterations',
                 'residual', 'status'):
        array = np.array(getattr(solution, name), copy=True)
        array[rows] = getattr(other, name)
        fields[name] = array
    fields['iterations'][rows] += np.asarray(solution.iterations)[rows]
    return type(solution)(**fields)


def _estimates(arm, Q_m, Tau, k, starts, tol, max_iterations, max_condition, max_force):
    """LoadPoseEstimate of each row, and the admissible solutions (q_k) of each."""
    candidates = _collect(arm, Q_m, Tau, k, starts, tol, max_iterations, max_force)
    main = candidates.main
    rigid = None
    out = []
    for i, found in enumerate(candidates.solutions):
        iterations, residual = int(main.iterations[i]), float(main.residual[i])
        nan3, nan4 = np.full(3, np.nan), np.full(4, np.nan)
        if len(found) == 1 and found[0][3] <= max_condition:
            f, q, tip, cond, iterations, residual = found[0]
            out.append(LoadPoseEstimate(f.copy(), q.copy(), k * q, tip.copy(), iterations, True,
                                        float(cond), residual, 'converged', ''))
            continue
        if len(found) == 1:
            status, cond = 'singular', float(found[0][3])
        elif len(found) > 1:
            status, cond = 'ambiguous', float(found[0][3])
        elif candidates.rejected[i]:
            status, cond = 'out_of_range', math.nan
        else:
            if rigid is None:  # condition at the rigid arm, for the failures
                q = np.zeros((len(Q_m), 7))
                q[:, _M] = Q_m
                rigid = _condition_numbers(arm.fk_and_jacobian_batch(q)[1])
            cond = float(rigid[i])
            status = 'singular' if cond > max_condition else str(main.status[i])
        reason = _REASONS[status].format(
            cond=cond, max_cond=max_condition, max_it=max_iterations, res=residual,
            n=len(found), loads=_fmt(s[0] for s in found) if found
            else _fmt(candidates.rejected[i]), max_force=max_force)
        alternatives = tuple(s[0].copy() for s in found) if status == 'ambiguous' else ()
        out.append(LoadPoseEstimate(nan3, nan4, nan4.copy(), nan3.copy(), iterations, False,
                                    cond, residual, status, reason, alternatives))
    return out, candidates.solutions


def _check_arm_and_k(arm, stiffness):
    check_arm(arm)
    return check_stiffness(stiffness)


def estimate_load_and_pose(
    arm: object,
    q_m: npt.ArrayLike,
    tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    max_condition: float = DEFAULT_MAX_CONDITION,
    max_force: float = DEFAULT_MAX_FORCE,
) -> LoadPoseEstimate:
    """Tip load and spring deflections from motor angles and torques, Fig. 5 of 000_....

    Solves eqs (6)-(7) of 000_ce37cf035a0a87c6, ``U_m^T f = tau_m`` and ``U_k^T f = k q_k``,
    for f and q_k (tip moments zero, no gravity): Newton's method on the reduced residual from
    the rigid arm (``solve_load_newton``), a continuation in the torques where it fails
    (``solve_load_continuation``), and Newton from each of ``SEARCH_STARTS`` to look for other
    admissible solutions. A single sample: no history, so two admissible loads with the same
    torques cannot be told apart (``LoadTracker`` uses the history).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_m : array-like, shape (3,)
        Motor angles [rad], DH joints 1, 2, 5.
    tau_m : array-like, shape (3,)
        Motor (load) torques [N·m], DH joints 1, 2, 5: ``tau_m = U_m^T f``, the paper's eq. (6)
        (``joint_states.effort`` from ros2_control is the torque the motor applies,
        ``-tau_m``).
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or one per spring (DH joints 3, 4, 6, 7).
    tol : float, optional
        Residual tolerance on |K q_k - U_k^T f| [N·m], positive.
    max_iterations : int, optional
        Newton steps allowed per solve, >= 1.
    max_condition : float, optional
        Largest accepted condition number of U_m (the linear 3x3 block of J_m) at the
        solution; above it the estimate is refused with status ``'singular'``.
    max_force : float, optional
        Largest admissible |f| [N].

    Returns
    -------
    LoadPoseEstimate
        Estimates and diagnostics; the arrays are NaN unless ``converged``.

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values, non-positive stiffness, tolerances
        or force limit, or a condition limit below 1.
    """
    k = _check_arm_and_k(arm, stiffness)
    q_m = check_vector('q_m', q_m, 3, 'rad')
    tau_m = check_vector('tau_m', tau_m, 3, 'N·m')
    options = _check_options(tol, max_iterations, max_condition, max_force)
    return _estimates(arm, q_m[None], tau_m[None], k, SEARCH_STARTS, *options)[0][0]


def estimate_load_and_pose_batch(
    arm: object,
    Q_m: npt.ArrayLike,
    Tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    max_condition: float = DEFAULT_MAX_CONDITION,
    max_force: float = DEFAULT_MAX_FORCE,
) -> LoadPoseEstimateBatch:
    """``estimate_load_and_pose`` for N independent samples in one vectorized call.

    The same solves and search, every sample in one compiled pass; sample i of the result
    equals ``estimate_load_and_pose`` of row i. For a time series ``LoadTracker`` is the
    better estimator (it uses the history to tell apart loads that fit the same torques).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    Q_m : array-like, shape (N, 3)
        Motor angles [rad], DH joints 1, 2, 5, one sample per row.
    Tau_m : array-like, shape (N, 3)
        Motor (load) torques [N·m], eq. (6) convention.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared by all samples.
    tol, max_iterations, max_condition, max_force
        As in ``estimate_load_and_pose``.

    Returns
    -------
    LoadPoseEstimateBatch

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values or invalid options.
    """
    k = _check_arm_and_k(arm, stiffness)
    Q_m = check_rows('Q_m', Q_m, 3, 'rad')
    Tau = check_rows('Tau_m', Tau_m, 3, 'N·m')
    if Tau.shape != Q_m.shape:
        raise ValueError(f'expected Tau_m of shape {Q_m.shape} like Q_m, got {Tau.shape}')
    options = _check_options(tol, max_iterations, max_condition, max_force)
    estimates = _estimates(arm, Q_m, Tau, k, SEARCH_STARTS, *options)[0]
    stack = lambda name, n: np.array([getattr(e, name) for e in estimates]).reshape(-1, n)  # noqa: E731
    return LoadPoseEstimateBatch(
        stack('force', 3), stack('q_k', 4), stack('tau_k', 4), stack('tip_position', 3),
        np.array([e.iterations for e in estimates], dtype=np.int64),
        np.array([e.converged for e in estimates], dtype=bool),
        np.array([e.condition_number for e in estimates]),
        np.array([e.residual for e in estimates]),
        np.array([e.status for e in estimates]),
        tuple(e.reason for e in estimates), tuple(e.alternatives for e in estimates))


# --- streams ---------------------------------------------------------------------------------

# Indices of the tracker's options array (one float array: a compiled call takes few arguments).
_REACH_FACTOR, _MIN_REACH, _TOL, _MAX_FORCE, _MAX_MOTOR_STEP, _MAX_TORQUE_STEP = range(6)


@njit(cache=True, error_model='numpy')
def _q_distance(a, b):
    """max |a_i - b_i| of two q_k [rad]."""
    d = 0.0
    for i in range(4):
        d = max(d, abs(a[i] - b[i]))
    return d


@njit(cache=True, error_model='numpy')
def _tracker_step(dh_table, k, q_m, tau_m, previous_q_m, previous_tau_m, branches, motion,
                  directions, options, max_iterations):
    """One warm step of ``LoadTracker``: the branches that continue, in compiled code.

    Returns ``(n, q_k, force, tip, motion, directions, condition, iterations, residual)`` of
    the n solutions kept, in the order ``LoadTracker`` documents (the continuation of each
    branch, then what lies within its reach); n = -1 when the input jumped (a cold start is
    due), n = 0 when every branch was lost.
    """
    for i in range(3):
        if not (abs(q_m[i] - previous_q_m[i]) <= options[_MAX_MOTOR_STEP]
                and abs(tau_m[i] - previous_tau_m[i]) <= options[_MAX_TORQUE_STEP]):
            return (-1, np.empty((0, 4)), np.empty((0, 3)), np.empty((0, 3)), np.empty(0),
                    np.empty((0, 4)), np.empty(0), 0, math.nan)
    reach_factor, min_reach = options[_REACH_FACTOR], options[_MIN_REACH]
    n = branches.shape[0]
    rows = 3 * n  # starts: p (rows 0..n-1), p + R v, p - R v
    Q, F, T = np.empty((rows, 4)), np.empty((rows, 3)), np.empty((rows, 3))
    J = np.empty((rows, 6, 7))
    ok = np.zeros(rows, np.bool_)
    iterations, residuals = np.zeros(rows, np.int64), np.zeros(rows)
    start = np.empty(4)
    for b in range(n):
        reach = max(reach_factor * motion[b], min_reach)
        for part in range(3):
            sign = 0.0 if part == 0 else (1.0 if part == 1 else -1.0)
            for s in range(4):
                start[s] = branches[b, s] + sign * reach * directions[b, s]
            row = part * n + b
            status, iterations[row], residuals[row] = newton_load_sample(
                dh_table, q_m, tau_m, k, start, options[_TOL], max_iterations, Q[row], F[row],
                T[row], J[row])
            size = F[row, 0] ** 2 + F[row, 1] ** 2 + F[row, 2] ** 2
            ok[row] = status == 0 and size <= options[_MAX_FORCE] ** 2
    kept, kept_motion = np.empty(rows, np.int64), np.empty(rows)
    m = 0
    for b in range(n):  # the continuation of each branch, then what lies within its reach
        if not ok[b]:
            continue
        step = _q_distance(Q[b], branches[b])
        radius = max(reach_factor * max(step, motion[b]), min_reach)
        for part in range(3):
            row = part * n + b
            if not (ok[row] and _q_distance(Q[row], Q[b]) <= radius):
                continue
            new = True
            for t in range(m):
                if not _q_distance(Q[row], Q[kept[t]]) > _SAME:
                    new = False
                    break
            if new:
                kept[m] = row
                kept_motion[m] = step if part == 0 else radius
                m += 1
    q_k, force, tip = np.empty((m, 4)), np.empty((m, 3)), np.empty((m, 3))
    direction, condition = np.empty((m, 4)), np.empty(m)
    for i in range(m):
        r = kept[i]
        q_k[i], force[i], tip[i] = Q[r], F[r], T[r]
        condition[i] = conditioning_sample(J[r], F[r], k, direction[i])[0]
    first = kept[0] if m else 0
    return (m, q_k, force, tip, kept_motion[:m].copy(), direction, condition,
            iterations[first], residuals[first])



class LoadTracker:
    """Streaming load and pose estimation that follows one branch of solutions.

    Each ``update`` starts Newton (``solve_load_newton``) from the previous estimate, so that
    it converges to the admissible solution continuous with it (the nearest in q_k), and from
    the two points p +- R v, with p the previous estimate, v the direction of the smallest
    singular value of the reduced Newton matrix D there and R the reach (``reach_factor``
    times the last change of the estimate, at least ``min_reach``): on a fold of f -> tau_m
    the other solution that meets the tracked one lies along v, and Newton from these points
    finds it once it is within about 2R. Every admissible solution within R of a tracked one
    is tracked as well: while more than one is, the torques alone and their history cannot
    tell which is the load, and the status is ``'ambiguous'`` (all of them in
    ``alternatives``), until all but one have left the admissible set.

    A cold start (``estimate_load_and_pose`` with its search) is made on the first sample,
    when the input jumps (a motor angle by more than ``max_motor_step`` or a torque by more
    than ``max_torque_step`` since the last sample), and when every tracked solution is lost;
    a cold start that finds several admissible loads tracks them all.

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad].
    max_motor_step : float, optional
        Largest change of a motor angle between samples still followed [rad].
    max_torque_step : float, optional
        Largest change of a motor torque between samples still followed [N·m].
    reach_factor : float, optional
        R as a multiple of the last change of the estimate (max over springs), >= 1.
    min_reach : float, optional
        Smallest R [rad], positive.
    tol, max_iterations, max_condition, max_force
        As in ``estimate_load_and_pose``.

    Raises
    ------
    ValueError
        On an invalid arm, stiffness or option.

    Notes
    -----
    Not thread-safe: one tracker per stream.
    """

    def __init__(
        self,
        arm: object,
        stiffness: npt.ArrayLike,
        *,
        max_motor_step: float = 0.05,
        max_torque_step: float = 5.0,
        reach_factor: float = 4.0,
        min_reach: float = 1e-4,
        tol: float = DEFAULT_TOLERANCE,
        max_iterations: int = DEFAULT_MAX_ITERATIONS,
        max_condition: float = DEFAULT_MAX_CONDITION,
        max_force: float = DEFAULT_MAX_FORCE,
    ) -> None:
        self._k = _check_arm_and_k(arm, stiffness)
        self._arm = arm
        self._options = _check_options(tol, max_iterations, max_condition, max_force)
        for name, value in (('max_motor_step', max_motor_step),
                            ('max_torque_step', max_torque_step), ('min_reach', min_reach)):
            if not (math.isfinite(float(value)) and float(value) > 0.0):
                raise ValueError(f'expected {name} positive and finite, got {value!r}')
        if not (math.isfinite(float(reach_factor)) and float(reach_factor) >= 1.0):
            raise ValueError(f'expected reach_factor >= 1, got {reach_factor!r}')
        options = np.empty(6)
        options[[_REACH_FACTOR, _MIN_REACH, _TOL, _MAX_FORCE, _MAX_MOTOR_STEP,
                 _MAX_TORQUE_STEP]] = (reach_factor, min_reach, self._options[0],
                                       self._options[3], max_motor_step, max_torque_step)
        self._step_options = options
        self._k = np.require(self._k, np.float64, ['C', 'W'])
        self.reset()

    def reset(self) -> None:
        """Forget the history: the next update starts cold."""
        self._input: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
        self._branches = np.empty((0, 4))  # tracked solutions q_k [rad]
        self._motion = np.empty(0)  # last change of each [rad]
        self._directions = np.empty((0, 4))  # fold direction of D at each
        self._cold_starts = 0

    @property
    def branches(self) -> npt.NDArray[np.float64]:
        """Tracked solutions q_k [rad], shape (n, 4): one, or several while ambiguous."""
        return self._branches.copy()

    @property
    def cold_starts(self) -> int:
        """Cold starts made since the last ``reset``."""
        return self._cold_starts

    def update(self, q_m: npt.ArrayLike, tau_m: npt.ArrayLike) -> LoadPoseEstimate:
        """Estimate the load of the next sample of the stream.

        Parameters
        ----------
        q_m : array-like, shape (3,)
            Motor angles [rad], DH joints 1, 2, 5.
        tau_m : array-like, shape (3,)
            Motor (load) torques [N·m], eq. (6) convention (``-joint_states.effort``).

        Returns
        -------
        LoadPoseEstimate

        Raises
        ------
        ValueError
            If ``q_m`` or ``tau_m`` is not 3 finite numbers (the history is kept).
        """
        # Copies: the history must not change with the caller's arrays, and the compiled
        # step takes one array type (C-contiguous, writable).
        q_m = np.array(check_vector('q_m', q_m, 3, 'rad'))
        tau_m = np.array(check_vector('tau_m', tau_m, 3, 'N·m'))
        previous, self._input = self._input, (q_m, tau_m)
        if previous is None or not self._branches.size:
            return self._cold(q_m, tau_m)
        return self._warm(q_m, tau_m, *previous)

    def _cold(self, q_m, tau_m) -> LoadPoseEstimate:
        self._cold_starts += 1
        estimates, solutions = _estimates(self._arm, q_m[None], tau_m[None], self._k,
                                          SEARCH_STARTS, *self._options)
        found = solutions[0]
        self._branches = np.array([s[1] for s in found]).reshape(-1, 4)
        self._motion = np.zeros(len(found))
        self._directions = np.zeros((len(found), 4))
        if found:
            q = np.zeros((len(found), 7))
            q[:, _M], q[:, _S] = q_m, self._branches
            J = self._arm.fk_and_jacobian_batch(q)[1]
            self._directions = conditioning(J, np.array([s[0] for s in found]), self._k)[2]
        return estimates[0]

    def _warm(self, q_m, tau_m, previous_q_m, previous_tau_m) -> LoadPoseEstimate:
        n, q_k, force, tip, motion, directions, cond, iterations, residual = _tracker_step(
            self._arm.dh_table, self._k, q_m, tau_m, previous_q_m, previous_tau_m,
            self._branches, self._motion, self._directions, self._step_options,
            self._options[1])
        if n <= 0:  # the input jumped, or every branch was lost
            return self._cold(q_m, tau_m)
        self._branches, self._motion, self._directions = q_k, motion, directions
        max_condition = self._options[2]
        condition = float(cond[0])
        if n == 1 and condition <= max_condition:
            return LoadPoseEstimate(force[0], q_k[0].copy(), self._k * q_k[0], tip[0],
                                    iterations, True, condition, residual, 'converged', '')
        nan3, nan4 = np.full(3, np.nan), np.full(4, np.nan)
        if n == 1:
            reason = _REASONS['singular'].format(cond=condition, max_cond=max_condition)
            return LoadPoseEstimate(nan3, nan4, nan4.copy(), nan3.copy(), iterations, False,
                                    condition, residual, 'singular', reason)
        forces = sorted(force, key=lambda f: float(np.linalg.norm(f)))
        reason = _REASONS['ambiguous'].format(n=len(forces), loads=_fmt(forces))
        return LoadPoseEstimate(nan3, nan4, nan4.copy(), nan3.copy(), iterations, False,
                                condition, residual, 'ambiguous', reason, tuple(forces))


# --- wrinkling guard --------------------------------------------------------------------------


def link_margins(
    moments: npt.ArrayLike, pressures: npt.ArrayLike, radius: float
) -> npt.NDArray[np.float64]:
    """Margin of each link against wrinkling, M_w(p) - moment (eq. 3 of 000_ce37cf035a0a87c6).

    Parameters
    ----------
    moments : array-like, shape (2,) or (N, 2)
        Bending moment on link 1 and link 2 [N·m], e.g. from ``link_moments``.
    pressures : float or array-like, broadcastable to ``moments``
        Inflation pressure of the links [Pa], positive: one for both, one per link (2,), or
        per sample.
    radius : float
        Link radius r [m], positive.

    Returns
    -------
    ndarray, shape of ``moments`` broadcast with ``pressures``
        ``(pi/4) pi p r^3 - moment`` [N·m]; negative where the link wrinkles and the PRB
        model of eq. (2) no longer holds.

    Raises
    ------
    ValueError
        On moments of the wrong shape, negative or non-finite moments, invalid pressures or
        radius, or shapes that do not broadcast.
    """
    m = np.asarray(moments, dtype=float)
    if m.ndim not in (1, 2) or m.shape[-1] != 2:
        raise ValueError(f'expected moments of shape (2,) or (N, 2) [N·m], got shape {m.shape}')
    if not (np.isfinite(m).all() and (m >= 0.0).all()):
        raise ValueError(f'expected moments non-negative and finite [N·m], got {m}')
    mw = wrinkling_moment(pressures, radius)
    try:
        shape = np.broadcast_shapes(np.shape(mw), m.shape)
    except ValueError:
        raise ValueError(f'expected pressures broadcastable to moments {m.shape}, got shape '
                         f'{np.shape(mw)}') from None
    return np.broadcast_to(mw, shape) - m
