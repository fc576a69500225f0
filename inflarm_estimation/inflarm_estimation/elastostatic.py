"""Load and pose estimation of the inflatable-link arm from motor torques (section 2.3).

Given the motor angles q_m and torques tau_m (DH joints 1, 2, 5) and the spring stiffness k,
find the tip force f [N] and the spring deflections q_k [rad] such that (eqs 5-7 of
000_ce37cf035a0a87c6, sign convention of ``inflarm_model.elastostatics``)::

    U_m(q)^T f = tau_m,        U_k(q)^T f = k q_k,        q = (q_m, q_k)

with U the linear rows of the Jacobian of eq. (4). Figure 5 of the paper iterates
f = U_m^-T tau_m, q_k = U_k^T f / k. That fixed point contracts only while the load's
geometric stiffness stays small against k; on the paper's arm it diverges for about 0.5 % of
random cases at 5-10 N and 8-10 % at 50-80 N. ``estimate_load_and_pose`` eliminates f (for a
given q_k it is the 3x3 solve above) and runs Newton's method on the reduced residual
g(q_k) = K q_k - U_k^T f(q_k), with the analytic derivative

    D = dg/dq_k = K - H_kk + U_k^T U_m^-T H_mk      (H: the load Hessian, see load_hessian)

and a backtracking line search on |g|^2, warm-started by one fixed-point step; a continuation
in the torques (0 -> tau_m) is the fallback when that fails.

Uniqueness. The estimate is a preimage of tau_m under the map f -> tau_m(f) (equilibrium
deflections included), whose Jacobian has the sign of det U_m det D; at f = 0 it is
sign det U_m(q_k = 0). Where the signs differ the solution lies beyond a fold of the map, and
by a degree argument at least two other loads give the same torques: such a solution is
refused with status ``'ambiguous'`` (its force is named in the reason). On the paper's arm
that is ~1-2 % of random cases at 50-100 N, and rare below (near the folded-elbow
singularity). A true load beyond a fold may also be returned as another load on the unfolded
sheet that fits the same torques (~1 % of random cases at 100 N in our tests, none at
<= 20 N): the motor torques alone cannot tell them apart.

Near-singular U_m (condition number over ``max_condition``), non-convergence, unstable
equilibria and ambiguity are reported with NaN estimates, never as numbers.

The hot path works on Python floats (small fixed-size algebra is faster there than through
numpy calls), one Pinocchio pass per iterate; the batch form runs the same arithmetic
elementwise on numpy arrays.
"""

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from inflarm_model.elastostatics import (  # the private helpers are this package's hot path
    DEFAULT_MAX_ITERATIONS,
    MOTOR_INDICES,
    SPRING_INDICES,
    _stable,
    _surely_stable,
    arm_kernel,
    check_rows,
    check_stiffness,
    float_list,
    link_moments,
)
from inflarm_model.link import wrinkling_moment

__all__ = [
    'DEFAULT_MAX_CONDITION',
    'DEFAULT_TOLERANCE',
    'LoadPoseEstimate',
    'LoadPoseEstimateBatch',
    'estimate_load_and_pose',
    'estimate_load_and_pose_batch',
    'link_margins',
    'link_moments',
]

# Residual tolerance on |K q_k - U_k^T f| [N·m]: with k ~ 170 N·m/rad it pins q_k to ~1e-12
# rad and the force to ~1e-9 N (less near a fold of tau_m(f), where f is ill-conditioned).
DEFAULT_TOLERANCE = 1e-10
# Largest accepted 2-norm condition number of U_m, the 3x3 linear block of J_m.
DEFAULT_MAX_CONDITION = 1e6
_MAX_STEP = 0.25  # largest Newton correction per spring and iteration [rad]
_MAX_DEFLECTION = 0.5 * math.pi  # beyond this the PRB model means nothing [rad]
_FINAL_STEP = 1e-6  # largest correction applied without re-evaluation [rad]
_MAX_HALVINGS = 12  # step lengths down to 2**-12
_ARMIJO = 1e-4
_CONTINUATION_STEPS = 8
_CONTINUATION_ITERATIONS = 20  # per increment; Newton from a nearby solution needs ~5
_RETRY = frozenset(('line_search', 'max_iterations', 'diverged'))
_HANDOFF = 32  # active samples below which the batch hands over to single solves
_NAN14 = (math.nan,) * 14
_isfinite = math.isfinite

_REASONS = {
    'converged': '',
    'singular': 'U_m (linear block of J_m) is near-singular: condition number {cond:.3g} over '
                'max_condition {max_cond:.3g}; the motor torques do not determine the load',
    'max_iterations': 'no convergence within max_iterations={max_it} (residual {res:.3g} N·m)',
    'line_search': 'no step reduced the residual {res:.3g} N·m: no equilibrium near the '
                   'rigid estimate matches these torques',
    'diverged': 'the iterates left the model range (|q_k| > pi/2 or non-finite)',
    'unstable': 'the equilibrium found is unstable (K - H_kk not positive definite): load '
                'beyond the stability limit of the links',
    'ambiguous': 'the solution found, f = {force} N, lies beyond a fold of tau_m(f): at least '
                 'two other loads give the same motor torques',
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
        Jacobian-based steps taken (fixed-point and Newton, fallback included).
    converged : bool
        True when the estimate is valid.
    condition_number : float
        2-norm condition number of U_m, the 3x3 linear block of J_m = [J_1 J_2 J_5], at the
        last evaluated configuration (q_k = 0 if the solve was refused there).
    residual : float
        max |K q_k - U_k^T f| [N·m]. When the last Newton correction (at most 1e-6 rad) is
        applied without another Jacobian pass, this is the bound predicted from the observed
        quadratic rate, max(k) |d_n|^3 / |d_(n-1)|^2.
    status : str
        ``'converged'``, ``'singular'``, ``'ambiguous'``, ``'unstable'``,
        ``'max_iterations'``, ``'line_search'`` or ``'diverged'``.
    reason : str
        Human-readable explanation; empty when converged.
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


def _make_estimate(values, iterations, converged, cond, residual, status, reason):
    """Build a LoadPoseEstimate from 14 floats (f, q_k, tau_k, tip), fast.

    One array, viewed four ways, and the instance dict filled directly: the frozen dataclass
    __init__ (ten object.__setattr__ calls) and four array constructions cost more than the
    whole of a warm Newton iteration.
    """
    v = np.array(values)
    estimate = object.__new__(LoadPoseEstimate)
    d = estimate.__dict__
    d['force'] = v[0:3]
    d['q_k'] = v[3:7]
    d['tau_k'] = v[7:11]
    d['tip_position'] = v[11:14]
    d['iterations'] = iterations
    d['converged'] = converged
    d['condition_number'] = cond
    d['residual'] = residual
    d['status'] = status
    d['reason'] = reason
    return estimate


# --- arithmetic on the flat Jacobian (floats, or arrays of shape (N,) in the batch) -----------


def _motor_load(j, t0, t1, t2):
    """Solve U_m^T f = tau_m (eq. 6) by the adjugate.

    U_m^T has rows a = u_1, b = u_2, c = u_5 (linear Jacobian columns of the motors), so its
    inverse has columns (b x c, c x a, a x b) / det, det = a . (b x c).

    Returns ``(f0, f1, f2, s, bcx, bcy, bcz, cax, cay, caz, abx, aby, abz)``, s = 1 / det.
    """
    ax, bx, cx = j[0], j[1], j[4]
    ay, by, cy = j[7], j[8], j[11]
    az, bz, cz = j[14], j[15], j[18]
    bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
    cax, cay, caz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax
    abx, aby, abz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    try:
        s = 1.0 / (ax * bcx + ay * bcy + az * bcz)
    except ZeroDivisionError:  # exactly singular U_m (floats; arrays give inf)
        s = math.inf
    return ((t0 * bcx + t1 * cax + t2 * abx) * s, (t0 * bcy + t1 * cay + t2 * aby) * s,
            (t0 * bcz + t1 * caz + t2 * abz) * s, s,
            bcx, bcy, bcz, cax, cay, caz, abx, aby, abz)


def _spring_residual(j, ml, q0, q1, q2, q3, k0, k1, k2, k3):
    """g = K q_k - U_k^T f (eq. 7 as a residual) [N·m], f = ml[0:3]."""
    f0, f1, f2 = ml[0], ml[1], ml[2]
    return (k0 * q0 - (j[2] * f0 + j[9] * f1 + j[16] * f2),
            k1 * q1 - (j[3] * f0 + j[10] * f1 + j[17] * f2),
            k2 * q2 - (j[5] * f0 + j[12] * f1 + j[19] * f2),
            k3 * q3 - (j[6] * f0 + j[13] * f1 + j[20] * f2))


def _newton_direction(j, ml, g0, g1, g2, g3, k0, k1, k2, k3):
    """Newton correction d solving D d = -g, D = dg/dq_k = K - H_kk + U_k^T U_m^-T H_mk.

    Load Hessian entries H_ab = z_a . (u_b x f) (a <= b, DH 0-based). Returns
    ``(d0, d1, d2, d3, det_D, w0, w1, w2)``: det D, whose sign times that of det U_m is the
    sign of det(d tau_m / d f), and w = H_mk d, with which the load follows the correction to
    first order, df = -U_m^-T w.
    """
    (_, _, ux2, ux3, ux4, ux5, ux6,
     _, _, uy2, uy3, uy4, uy5, uy6,
     _, _, uz2, uz3, uz4, uz5, uz6,
     _, zx1, zx2, zx3, zx4, zx5, zx6,
     _, zy1, zy2, zy3, zy4, zy5, zy6,
     _, zz1, zz2, zz3, zz4, zz5, zz6) = j
    f0, f1, f2, s, bcx, bcy, bcz, cax, cay, caz, abx, aby, abz = ml
    v2x, v2y, v2z = uy2 * f2 - uz2 * f1, uz2 * f0 - ux2 * f2, ux2 * f1 - uy2 * f0
    v3x, v3y, v3z = uy3 * f2 - uz3 * f1, uz3 * f0 - ux3 * f2, ux3 * f1 - uy3 * f0
    v4x, v4y, v4z = uy4 * f2 - uz4 * f1, uz4 * f0 - ux4 * f2, ux4 * f1 - uy4 * f0
    v5x, v5y, v5z = uy5 * f2 - uz5 * f1, uz5 * f0 - ux5 * f2, ux5 * f1 - uy5 * f0
    v6x, v6y, v6z = uy6 * f2 - uz6 * f1, uz6 * f0 - ux6 * f2, ux6 * f1 - uy6 * f0
    # H_mk, rows DH 0, 1, 4. Joint 1 turns about z_0, the base z axis, so H_0b = v_b . e_z.
    q00, q01, q02, q03 = v2z, v3z, v5z, v6z
    q10 = zx1 * v2x + zy1 * v2y + zz1 * v2z
    q11 = zx1 * v3x + zy1 * v3y + zz1 * v3z
    q12 = zx1 * v5x + zy1 * v5y + zz1 * v5z
    q13 = zx1 * v6x + zy1 * v6y + zz1 * v6z
    q20 = zx2 * v4x + zy2 * v4y + zz2 * v4z  # H_24: spring DH 2 is proximal to motor DH 4
    q21 = zx3 * v4x + zy3 * v4y + zz3 * v4z
    q22 = zx4 * v5x + zy4 * v5y + zz4 * v5z
    q23 = zx4 * v6x + zy4 * v6y + zz4 * v6z
    # X = U_m^-T H_mk, column by column through the adjugate.
    x00 = (bcx * q00 + cax * q10 + abx * q20) * s
    x10 = (bcy * q00 + cay * q10 + aby * q20) * s
    x20 = (bcz * q00 + caz * q10 + abz * q20) * s
    x01 = (bcx * q01 + cax * q11 + abx * q21) * s
    x11 = (bcy * q01 + cay * q11 + aby * q21) * s
    x21 = (bcz * q01 + caz * q11 + abz * q21) * s
    x02 = (bcx * q02 + cax * q12 + abx * q22) * s
    x12 = (bcy * q02 + cay * q12 + aby * q22) * s
    x22 = (bcz * q02 + caz * q12 + abz * q22) * s
    x03 = (bcx * q03 + cax * q13 + abx * q23) * s
    x13 = (bcy * q03 + cay * q13 + aby * q23) * s
    x23 = (bcz * q03 + caz * q13 + abz * q23) * s
    # D = K - H_kk + U_k^T X
    h23 = zx2 * v3x + zy2 * v3y + zz2 * v3z
    h25 = zx2 * v5x + zy2 * v5y + zz2 * v5z
    h26 = zx2 * v6x + zy2 * v6y + zz2 * v6z
    h35 = zx3 * v5x + zy3 * v5y + zz3 * v5z
    h36 = zx3 * v6x + zy3 * v6y + zz3 * v6z
    h56 = zx5 * v6x + zy5 * v6y + zz5 * v6z
    a00 = k0 - (zx2 * v2x + zy2 * v2y + zz2 * v2z) + ux2 * x00 + uy2 * x10 + uz2 * x20
    a01 = ux2 * x01 + uy2 * x11 + uz2 * x21 - h23
    a02 = ux2 * x02 + uy2 * x12 + uz2 * x22 - h25
    a03 = ux2 * x03 + uy2 * x13 + uz2 * x23 - h26
    a10 = ux3 * x00 + uy3 * x10 + uz3 * x20 - h23
    a11 = k1 - (zx3 * v3x + zy3 * v3y + zz3 * v3z) + ux3 * x01 + uy3 * x11 + uz3 * x21
    a12 = ux3 * x02 + uy3 * x12 + uz3 * x22 - h35
    a13 = ux3 * x03 + uy3 * x13 + uz3 * x23 - h36
    a20 = ux5 * x00 + uy5 * x10 + uz5 * x20 - h25
    a21 = ux5 * x01 + uy5 * x11 + uz5 * x21 - h35
    a22 = k2 - (zx5 * v5x + zy5 * v5y + zz5 * v5z) + ux5 * x02 + uy5 * x12 + uz5 * x22
    a23 = ux5 * x03 + uy5 * x13 + uz5 * x23 - h56
    a30 = ux6 * x00 + uy6 * x10 + uz6 * x20 - h26
    a31 = ux6 * x01 + uy6 * x11 + uz6 * x21 - h36
    a32 = ux6 * x02 + uy6 * x12 + uz6 * x22 - h56
    a33 = k3 - (zx6 * v6x + zy6 * v6y + zz6 * v6z) + ux6 * x03 + uy6 * x13 + uz6 * x23
    # Gaussian elimination without pivoting: D is K plus load terms an order of magnitude
    # smaller in the working range; a vanishing pivot gives a non-finite step, which the
    # caller rejects.
    b0, b1, b2, b3 = -g0, -g1, -g2, -g3
    r = a10 / a00
    a11, a12, a13, b1 = a11 - r * a01, a12 - r * a02, a13 - r * a03, b1 - r * b0
    r = a20 / a00
    a21, a22, a23, b2 = a21 - r * a01, a22 - r * a02, a23 - r * a03, b2 - r * b0
    r = a30 / a00
    a31, a32, a33, b3 = a31 - r * a01, a32 - r * a02, a33 - r * a03, b3 - r * b0
    r = a21 / a11
    a22, a23, b2 = a22 - r * a12, a23 - r * a13, b2 - r * b1
    r = a31 / a11
    a32, a33, b3 = a32 - r * a12, a33 - r * a13, b3 - r * b1
    r = a32 / a22
    a33, b3 = a33 - r * a23, b3 - r * b2
    d3 = b3 / a33
    d2 = (b2 - a23 * d3) / a22
    d1 = (b1 - a12 * d2 - a13 * d3) / a11
    d0 = (b0 - a01 * d1 - a02 * d2 - a03 * d3) / a00
    return (d0, d1, d2, d3, a00 * a11 * a22 * a33,
            q00 * d0 + q01 * d1 + q02 * d2 + q03 * d3,
            q10 * d0 + q11 * d1 + q12 * d2 + q13 * d3,
            q20 * d0 + q21 * d1 + q22 * d2 + q23 * d3)


def _gram_invariants(j, ml):
    """Trace, second invariant and determinant of U_m U_m^T (eigenvalues sigma_i^2)."""
    _, _, _, s, bcx, bcy, bcz, cax, cay, caz, abx, aby, abz = ml
    tr = (j[0] * j[0] + j[1] * j[1] + j[4] * j[4] + j[7] * j[7] + j[8] * j[8]
          + j[11] * j[11] + j[14] * j[14] + j[15] * j[15] + j[18] * j[18])
    c2 = (bcx * bcx + bcy * bcy + bcz * bcz + cax * cax + cay * cay + caz * caz
          + abx * abx + aby * aby + abz * abz)
    return tr, c2, 1.0 / (s * s)


def _condition_number(j, ml) -> float:
    """2-norm condition number sigma_1 / sigma_3 of U_m from its Gram invariants.

    The Gram eigenvalues l are the roots of l^3 - tr l^2 + c2 l - det^2 = 0: the largest from
    the trigonometric solution (well conditioned), the smallest from the quadratic left over,
    in its cancellation-free form.
    """
    tr, c2, det2 = _gram_invariants(j, ml)
    if not (det2 > 0.0 and _isfinite(det2)):
        return math.inf
    m = tr / 3.0
    p = c2 / 3.0 - m * m  # depressed cubic t^3 + 3 p t + 2 h = 0, l = t + m
    h = m * c2 / 2.0 - m * m * m - det2 / 2.0
    if p >= 0.0:
        l1 = m
    else:
        r = math.sqrt(-p)
        l1 = m + 2.0 * r * math.cos(math.acos(max(-1.0, min(1.0, -h / (r * r * r)))) / 3.0)
    rest = tr - l1  # l2 + l3
    prod = det2 / l1  # l2 l3
    l2 = 0.5 * (rest + math.sqrt(max(rest * rest - 4.0 * prod, 0.0)))
    l3 = prod / l2 if l2 > 0.0 else 0.0
    return math.sqrt(l1 / l3) if l3 > 0.0 else math.inf


def _condition_number_batch(j, ml):
    """Vectorized ``_condition_number``."""
    tr, c2, det2 = _gram_invariants(j, ml)
    with np.errstate(divide='ignore', invalid='ignore'):
        m = tr / 3.0
        p = np.minimum(c2 / 3.0 - m * m, 0.0)
        h = m * c2 / 2.0 - m * m * m - det2 / 2.0
        r = np.sqrt(-p)
        c = np.clip(np.where(r > 0.0, -h / (r * r * r), 1.0), -1.0, 1.0)
        l1 = m + 2.0 * r * np.cos(np.arccos(c) / 3.0)
        rest = tr - l1
        prod = det2 / l1
        l2 = 0.5 * (rest + np.sqrt(np.maximum(rest * rest - 4.0 * prod, 0.0)))
        l3 = np.where(l2 > 0.0, prod / l2, 0.0)
        cond = np.sqrt(l1 / l3)
    return np.where((det2 > 0.0) & (l3 > 0.0) & np.isfinite(cond), cond, np.inf)


def _frobenius_ok(j, ml, max_condition):
    """Cheap refusal test: kappa_F <= 3 kappa_2, so failing it means kappa_2 > max_condition."""
    tr, c2, det2 = _gram_invariants(j, ml)
    return tr * c2 <= 9.0 * max_condition * max_condition * det2


# --- the solver ------------------------------------------------------------------------------


def _solve(kernel, t0, t1, t2, k0, k1, k2, k3, q0, q1, q2, q3, tol, max_iterations,
           max_condition, fixed_point, warm_start):
    """Solve the reduced equilibrium g(q_k) = 0 from q_k = (q0, q1, q2, q3).

    The kernel holds the motor angles. Returns ``(q, ml, j, correction, iterations,
    residual, status, s0, det_d)``: the last evaluated iterate q (4-tuple), its ``_motor_load``
    tuple and flat Jacobian, an optional last Newton correction not yet applied, the residual
    max |g| [N·m], the status, 1/det U_m at the start and det D of the last Newton matrix (1 if
    none). When the rigid estimate is refused as singular, ``j`` is None.
    """
    jac = kernel.spring_jacobian_flat
    j = jac(q0, q1, q2, q3)
    ml = _motor_load(j, t0, t1, t2)
    s0 = ml[3]
    det_d = 1.0
    if q0 == 0.0 and q1 == 0.0 and q2 == 0.0 and q3 == 0.0 and not (
            _isfinite(s0) and _frobenius_ok(j, ml, max_condition)):
        return (q0, q1, q2, q3), ml, None, None, 0, math.inf, 'singular', s0, det_d
    g0, g1, g2, g3 = _spring_residual(j, ml, q0, q1, q2, q3, k0, k1, k2, k3)
    merit = g0 * g0 + g1 * g1 + g2 * g2 + g3 * g3
    residual = max(abs(g0), abs(g1), abs(g2), abs(g3))
    kmax = max(k0, k1, k2, k3)
    previous = 0.0  # size of the previous full Newton step
    iterations = 0
    status = 'converged'
    while residual > tol:
        if iterations >= max_iterations:
            status = 'max_iterations'
            break
        iterations += 1
        newton = not (fixed_point or warm_start)
        if newton:
            d0, d1, d2, d3, det_d, w0, w1, w2 = _newton_direction(
                j, ml, g0, g1, g2, g3, k0, k1, k2, k3)
        else:  # Fig. 5: q_k <- U_k^T f / k, i.e. q_k - g / k
            d0, d1, d2, d3 = -g0 / k0, -g1 / k1, -g2 / k2, -g3 / k3
        size = max(abs(d0), abs(d1), abs(d2), abs(d3))
        if not _isfinite(size):
            status = 'line_search'
            break
        if newton and size <= _FINAL_STEP and size * size * size * kmax <= tol * previous ** 2:
            # Quadratic regime: the residual after this correction is below tol (predicted from
            # the last two steps), so it is applied without another Jacobian pass.
            return ((q0, q1, q2, q3), ml, j, (d0, d1, d2, d3, w0, w1, w2), iterations,
                    kmax * size * size * size / previous ** 2, 'converged', s0, det_d)
        if size > _MAX_STEP and not fixed_point:
            scale = _MAX_STEP / size
            d0, d1, d2, d3 = d0 * scale, d1 * scale, d2 * scale, d3 * scale
        alpha = 1.0
        for _ in range(_MAX_HALVINGS):
            p0, p1, p2, p3 = q0 + alpha * d0, q1 + alpha * d1, q2 + alpha * d2, q3 + alpha * d3
            jt = jac(p0, p1, p2, p3)
            mlt = _motor_load(jt, t0, t1, t2)
            h0, h1, h2, h3 = _spring_residual(jt, mlt, p0, p1, p2, p3, k0, k1, k2, k3)
            trial = h0 * h0 + h1 * h1 + h2 * h2 + h3 * h3
            if not newton or trial <= (1.0 - 2.0 * _ARMIJO * alpha) * merit:
                break
            alpha *= 0.5
        else:
            status = 'line_search'
            break
        if warm_start:
            warm_start = False
            if not trial < merit:  # the warm start did not help: Newton from here instead
                jac(q0, q1, q2, q3)  # restore the kernel's tip to the current iterate
                continue
        if not (_isfinite(trial) and max(abs(p0), abs(p1), abs(p2), abs(p3)) <= _MAX_DEFLECTION):
            status = 'diverged'
            break
        previous = size if newton and alpha == 1.0 and size <= _MAX_STEP else 0.0
        q0, q1, q2, q3, j, ml, merit = p0, p1, p2, p3, jt, mlt, trial
        g0, g1, g2, g3 = h0, h1, h2, h3
        residual = max(abs(h0), abs(h1), abs(h2), abs(h3))
    return (q0, q1, q2, q3), ml, j, None, iterations, residual, status, s0, det_d


def _continuation(kernel, t0, t1, t2, k0, k1, k2, k3, tol, max_iterations, max_condition):
    """Fallback: follow the solution from the unloaded arm while the torques grow to tau_m.

    Solves for lambda tau_m, lambda = 1/8, 2/8, ..., 1, each by Newton from the previous
    solution, halving an increment that fails. Slower; used only when the direct solve fails.
    Returns what ``_solve`` returns, iterations summed; on failure, the last failed attempt.
    """
    q = (0.0, 0.0, 0.0, 0.0)
    lam, step, total = 0.0, 1.0 / _CONTINUATION_STEPS, 0
    while True:
        target = min(1.0, lam + step)
        result = _solve(kernel, target * t0, target * t1, target * t2, k0, k1, k2, k3, *q, tol,
                        min(max_iterations, _CONTINUATION_ITERATIONS), max_condition, False,
                        False)
        total += result[4]
        status = result[6]
        if status == 'converged':
            lam, q, d = target, result[0], result[3]
            if d is not None:
                q = (q[0] + d[0], q[1] + d[1], q[2] + d[2], q[3] + d[3])
        else:
            step *= 0.5
        if lam >= 1.0 or status == 'singular' or step < 1.0 / (8 * _CONTINUATION_STEPS):
            break
    return (*result[:4], total, *result[5:])


def _on_main_sheet(solution) -> bool:
    """Whether a converged solve lies on the sheet of tau_m(f) connected to f = 0.

    sign det(d tau_m / d f) = sign(det U_m det D) at a stable equilibrium (Schur complements
    of the 7x7 Newton matrix; det(K - H_kk) > 0); at f = 0 it is sign det U_m(q_k = 0).
    """
    return solution[1][3] * solution[8] * solution[7] > 0.0


def _corrected(solution):
    """(q, f) of a converged solve with its pending Newton correction applied to first order."""
    (q0, q1, q2, q3), ml, _, correction = solution[:4]
    f0, f1, f2, s, bcx, bcy, bcz, cax, cay, caz, abx, aby, abz = ml
    if correction is None:
        return (q0, q1, q2, q3), (f0, f1, f2)
    d0, d1, d2, d3, w0, w1, w2 = correction
    return ((q0 + d0, q1 + d1, q2 + d2, q3 + d3),
            (f0 - (bcx * w0 + cax * w1 + abx * w2) * s, f1 - (bcy * w0 + cay * w1 + aby * w2) * s,
             f2 - (bcz * w0 + caz * w1 + abz * w2) * s))


# --- single estimate -------------------------------------------------------------------------


def estimate_load_and_pose(
    arm: object,
    q_m: npt.ArrayLike,
    tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    method: str = 'newton',
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> LoadPoseEstimate:
    """Tip load and spring deflections from motor angles and torques, Fig. 5 of 000_....

    Solves eqs (5)-(7) of 000_ce37cf035a0a87c6, ``U_m^T f = tau_m`` and ``U_k^T f = k q_k``,
    for f and q_k (tip moments zero, no gravity). Sign convention: ``tau_m`` is the load
    torque on each motor axis, ``tau_m = U_m^T f`` (see ``inflarm_model.elastostatics``).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    q_m : array-like, shape (3,)
        Motor angles [rad], DH joints 1, 2, 5.
    tau_m : array-like, shape (3,)
        Motor (load) torques [N·m], DH joints 1, 2, 5.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared or one per spring (DH joints 3, 4, 6, 7).
    method : {'newton', 'fixed_point'}, optional
        ``'newton'`` (default): one fixed-point warm-start step, then Newton on the reduced
        residual with a line search, and a continuation in the torques (0 -> tau_m) if that
        fails.
        ``'fixed_point'``: the paper's plain iteration of Fig. 5, kept to show where it fails
        (no ambiguity check either).
    tol : float, optional
        Residual tolerance on |K q_k - U_k^T f| [N·m], positive.
    max_iterations : int, optional
        Jacobian-based steps allowed per solve, >= 1.
    max_condition : float, optional
        Largest accepted condition number of U_m (the linear 3x3 block of J_m); above it the
        estimate is refused with status ``'singular'``.

    Returns
    -------
    LoadPoseEstimate
        Estimates and diagnostics; the arrays are NaN unless ``converged``.

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values, non-positive stiffness, tolerances
        or condition limit, or an unknown method.
    """
    kernel = arm_kernel(arm)
    m0, m1, m2 = float_list('q_m', q_m, 3, 'rad')
    t0, t1, t2 = float_list('tau_m', tau_m, 3, 'N·m')
    k0, k1, k2, k3 = check_stiffness(stiffness)
    tol, max_condition = _check_options(method, tol, max_iterations, max_condition)
    fixed_point = method == 'fixed_point'
    kernel.set_motors(m0, m1, m2)
    solution = _solve(kernel, t0, t1, t2, k0, k1, k2, k3, 0.0, 0.0, 0.0, 0.0, tol,
                      max_iterations, max_condition, fixed_point, True)
    if solution[6] in _RETRY and not fixed_point:
        # The direct solve failed: follow the branch of the unloaded arm by continuation.
        retry = _continuation(kernel, t0, t1, t2, k0, k1, k2, k3, tol, max_iterations,
                              max_condition)
        solution = (*retry[:4], solution[4] + retry[4], *retry[5:])
    q, ml, j, correction, iterations, residual, status = solution[:7]
    if j is None:  # refused at the rigid estimate
        return _failed('singular', 0, math.inf, residual, max_condition, max_iterations)
    cond = _condition_number(j, ml)
    if cond > max_condition:
        status = 'singular'
    elif status == 'converged' and not fixed_point and not _on_main_sheet(solution):
        # Beyond a fold of tau_m(f): its degree (+-1, from f = 0) counts this solution with
        # the opposite sign, so at least two other loads give the same motor torques.
        _, force = _corrected(solution)
        return _failed('ambiguous', iterations, cond, residual, max_condition, max_iterations,
                       force=_fmt(force))
    if status != 'converged':
        return _failed(status, iterations, cond, residual, max_condition, max_iterations)
    (q0, q1, q2, q3), (f0, f1, f2) = _corrected(solution)
    if not (_surely_stable(j, f0, f1, f2, min(k0, k1, k2, k3))
            or _stable(j, f0, f1, f2, k0, k1, k2, k3)):
        return _failed('unstable', iterations, cond, residual, max_condition, max_iterations)
    x, y, z = kernel.tip_position()
    if correction is not None:  # the tip follows the last correction to first order
        d0, d1, d2, d3 = correction[:4]
        x += j[2] * d0 + j[3] * d1 + j[5] * d2 + j[6] * d3
        y += j[9] * d0 + j[10] * d1 + j[12] * d2 + j[13] * d3
        z += j[16] * d0 + j[17] * d1 + j[19] * d2 + j[20] * d3
    return _make_estimate(
        (f0, f1, f2, q0, q1, q2, q3, k0 * q0, k1 * q1, k2 * q2, k3 * q3, x, y, z),
        iterations, True, cond, residual, 'converged', '')


def _check_options(
    method: str, tol: float, max_iterations: int, max_condition: float
) -> tuple[float, float]:
    """Validate the solver options; return (tol, max_condition) as floats."""
    if method != 'newton' and method != 'fixed_point':
        raise ValueError(f"expected method 'newton' or 'fixed_point', got {method!r}")
    tol, max_condition = float(tol), float(max_condition)
    if not (_isfinite(tol) and tol > 0.0):
        raise ValueError(f'expected tol positive and finite [N·m], got {tol!r}')
    if type(max_iterations) is not int or max_iterations < 1:
        raise ValueError(f'expected max_iterations an integer >= 1, got {max_iterations!r}')
    if not max_condition >= 1.0:
        raise ValueError(f'expected max_condition >= 1, got {max_condition!r}')
    return tol, max_condition


def _fmt(v) -> str:
    return '[' + ', '.join(f'{x:.4g}' for x in v) + ']'


def _failed(status: str, iterations: int, cond: float, residual: float, max_condition: float,
            max_iterations: int, force: str = '') -> LoadPoseEstimate:
    reason = _REASONS[status].format(cond=cond, max_cond=max_condition, max_it=max_iterations,
                                     res=residual, force=force)
    return _make_estimate(_NAN14, iterations, False, cond, residual, status, reason)


# --- batch ------------------------------------------------------------------------------------


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
        2-norm condition number of U_m at the last evaluated configuration.
    residual : ndarray, shape (N,)
        max |K q_k - U_k^T f| [N·m] at the returned configuration.
    status : ndarray of str, shape (N,)
        As ``LoadPoseEstimate.status``.
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


def estimate_load_and_pose_batch(
    arm: object,
    Q_m: npt.ArrayLike,
    Tau_m: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    *,
    tol: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> LoadPoseEstimateBatch:
    """``estimate_load_and_pose`` (Newton) for N samples, vectorized over N (e.g. a whole bag).

    The same warm start, Newton direction, line search and checks as the single form, run
    elementwise on numpy arrays with Jacobians from ``arm.jacobian_batch``; samples leave the
    active set as they finish. The rare samples whose direct solve fails go through the single
    form (continuation fallback).

    Parameters
    ----------
    arm : FlexibleArm
        The 7-DOF arm of Table 2.
    Q_m : array-like, shape (N, 3)
        Motor angles [rad], DH joints 1, 2, 5, one sample per row.
    Tau_m : array-like, shape (N, 3)
        Motor (load) torques [N·m], DH joints 1, 2, 5.
    stiffness : float or array-like, shape (4,)
        Spring stiffness [N·m/rad], shared by all samples.
    tol, max_iterations, max_condition
        As in ``estimate_load_and_pose``.

    Returns
    -------
    LoadPoseEstimateBatch

    Raises
    ------
    ValueError
        On arguments of the wrong shape, non-finite values or non-positive stiffness.
    """
    arm_kernel(arm)  # validates the arm layout
    Q_m = check_rows('Q_m', Q_m, 3, 'rad')
    Tau = check_rows('Tau_m', Tau_m, 3, 'N·m')
    if Tau.shape[0] != Q_m.shape[0]:
        raise ValueError(f'expected Tau_m of shape ({Q_m.shape[0]}, 3) like Q_m, '
                         f'got {Tau.shape}')
    k = check_stiffness(stiffness)
    tol, max_condition = _check_options('newton', tol, max_iterations, max_condition)
    N = Q_m.shape[0]
    k0, k1, k2, k3 = k
    kcol = np.array(k)[:, None]

    Q = np.zeros((N, 7))
    Q[:, MOTOR_INDICES] = Q_m
    iterations = np.zeros(N, dtype=np.int64)
    residual = np.full(N, np.inf)
    cond = np.full(N, np.inf)
    status = np.full(N, 'max_iterations', dtype='<U14')
    F = np.full((N, 3), np.nan)
    tips = np.full((N, 3), np.nan)
    det_d = np.ones(N)  # det D of the last Newton matrix (1: none formed)
    kmax = max(k)

    def evaluate(idx, Qi):
        poses, J = arm.fk_and_jacobian_batch(Qi)
        # The flat layout, one contiguous row per entry (strided rows triple the arithmetic).
        j = np.ascontiguousarray(J.transpose(1, 2, 0).reshape(42, len(idx)))
        ml = np.array(_motor_load(j, *Tau[idx].T))
        g = _spring_residual(j, ml, *Qi[:, SPRING_INDICES].T, k0, k1, k2, k3)
        return j, ml, np.array(g), poses[:, :3, 3]

    def finish(mask, why, force=None, tip_at=None):
        """Take the masked active samples out, recording status, load, tip and condition."""
        if not mask.any():
            return
        idx = active[mask]
        jm, mlm = j[:, mask], ml[:, mask]
        cond[idx] = _condition_number_batch(jm, mlm)
        F[idx] = mlm[:3].T if force is None else force
        tips[idx] = tip[mask] if tip_at is None else tip_at
        if why == 'converged':  # the checks of the single form
            f0, f1, f2 = F[idx].T
            stable = _surely_stable(jm, f0, f1, f2, min(k))
            rest = ~stable
            stable[rest] = _stable(jm[:, rest], f0[rest], f1[rest], f2[rest], k0, k1, k2, k3)
            why = np.where(~(cond[idx] <= max_condition), 'singular', np.where(
                ~(mlm[3] * det_d[idx] * s0[idx] > 0.0), 'ambiguous', np.where(
                    stable, 'converged', 'unstable')))
        status[idx] = why

    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        active = np.arange(N)
        j, ml, g, tip = evaluate(active, Q)
        s0 = ml[3].copy()  # 1/det U_m at q_k = 0
        warm = np.ones(N, dtype=bool)
        previous = np.zeros(N)  # size of the previous full Newton step
        out = ~(np.isfinite(s0) & _frobenius_ok(j, ml, max_condition))
        why = 'singular'
        for _ in range(max_iterations + 1):
            if why is not None:
                finish(out, why)
            res = np.abs(g).max(axis=0)
            residual[active[~out]] = res[~out]
            done = ~out & (res <= tol)
            finish(done, 'converged')
            over = ~(out | done) & (iterations[active] >= max_iterations)
            finish(over, 'max_iterations')
            keep = ~(out | done | over)
            if not keep.all():
                active, j, ml, g, tip, warm, previous = (
                    active[keep], j[:, keep], ml[:, keep], g[:, keep], tip[keep], warm[keep],
                    previous[keep])
            if active.size <= _HANDOFF:
                # A vectorized pass costs about as much for a few samples as for thousands:
                # the last stragglers go through the single form.
                status[active] = 'handoff'
                break
            iterations[active] += 1
            if warm.all():  # first round: Fig. 5 warm-start steps only
                d = -g / kcol
                final = np.zeros(active.size, dtype=bool)
            else:
                d0, d1, d2, d3, det, w0, w1, w2 = _newton_direction(j, ml, *g, k0, k1, k2, k3)
                d = np.array((d0, d1, d2, d3))
                d[:, warm] = -g[:, warm] / kcol  # Fig. 5 warm-start step
                det_d[active[~warm]] = det[~warm]
            size = np.abs(d).max(axis=0)
            # As in the single form, the last Newton correction of the quadratic regime is
            # applied without another pass.
            if not warm.all():
                final = ~warm & (size <= _FINAL_STEP) & (size**3 * kmax <= tol * previous**2)
            if final.any():
                idx = active[final]
                df = np.array((w0, w1, w2))[:, final]
                m = ml[:, final]
                s, cols = m[3], m[4:].reshape(3, 3, -1)  # adjugate columns bc, ca, ab
                force = (m[:3] - s * (cols[0] * df[0] + cols[1] * df[1] + cols[2] * df[2])).T
                jf, dk = j[:, final], d[:, final]
                shift = np.array([jf[2 + 7 * r] * dk[0] + jf[3 + 7 * r] * dk[1]
                                  + jf[5 + 7 * r] * dk[2] + jf[6 + 7 * r] * dk[3]
                                  for r in range(3)])
                Q[np.ix_(idx, SPRING_INDICES)] += dk.T
                residual[idx] = kmax * size[final] ** 3 / previous[final] ** 2
                finish(final, 'converged', force, tip[final] + shift.T)
            d *= np.minimum(1.0, _MAX_STEP / size)
            # Full steps only: a sample whose step is non-finite or fails the Armijo test goes
            # through the single form (line search), rather than costing a pass per halving.
            bad = ~np.isfinite(size)
            status[active[bad]] = 'handoff'
            leave = final | bad
            if leave.any():
                keep = ~leave
                active, j, ml, g, tip, warm, d, size = (
                    active[keep], j[:, keep], ml[:, keep], g[:, keep], tip[keep], warm[keep],
                    d[:, keep], size[keep])
            merit = (g * g).sum(axis=0)
            Qt = Q[active]
            Qt[:, SPRING_INDICES] += d.T
            jt, mlt, gt, tipt = evaluate(active, Qt)
            trial = (gt * gt).sum(axis=0)
            ok = warm | (trial <= (1.0 - 2.0 * _ARMIJO) * merit)
            # A warm start that does not reduce the residual is dropped: Newton from here.
            stay = warm & ~(trial < merit)
            if stay.any():  # keep their current iterate (few)
                Qt[stay], jt[:, stay], mlt[:, stay], gt[:, stay], tipt[stay] = (
                    Q[active[stay]], j[:, stay], ml[:, stay], g[:, stay], tip[stay])
            Q[active] = Qt
            previous = np.where(~warm & ~stay & (size <= _MAX_STEP), size, 0.0)
            j, ml, g, tip = jt, mlt, gt, tipt
            handoff = ~ok
            status[active[handoff]] = 'handoff'
            diverged = ok & ~stay & ~(np.isfinite(g).all(axis=0) & (
                np.abs(Qt[:, SPRING_INDICES]).max(axis=1) <= _MAX_DEFLECTION))
            finish(diverged, 'diverged')
            warm[:] = False
            out = handoff | diverged  # already recorded; leave the active set next round
            why = None

    Q_k = Q[:, SPRING_INDICES].copy()
    # Stragglers and failed direct solves (rare) go through the single form, which adds the
    # continuation fallback.
    for i in np.flatnonzero(np.isin(status, (*_RETRY, 'handoff'))):
        one = estimate_load_and_pose(arm, Q_m[i], Tau[i], stiffness, tol=tol,
                                     max_iterations=max_iterations,
                                     max_condition=max_condition)
        F[i], Q_k[i], tips[i] = one.force, one.q_k, one.tip_position
        iterations[i] = one.iterations
        cond[i], residual[i], status[i] = one.condition_number, one.residual, one.status
    ok = status == 'converged'
    Q_k[~ok] = np.nan
    tips[~ok] = np.nan
    F[~ok] = np.nan
    return LoadPoseEstimateBatch(F, Q_k, Q_k * np.array(k), tips, iterations, ok, cond,
                                 residual, status)


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
