"""Physics of one inflatable link: wrinkling, beam deflection, stiffness and Young's modulus.

Pure numpy/scipy core (no ROS). SI units throughout: Pa, m, N, N·m, rad.

The link is a thin-walled PVC-coated fabric tube closed by two rigid caps (section 2.1 and
section 3 of 000_ce37cf035a0a87c6). Three models of it are used:

- the wrinkling moment ``M_w`` of eq. (3): the bending moment at which the first wrinkle appears
  and beyond which the moment no longer grows with the deflection;
- the Le van–Wielgosz inflatable-beam deflection of eq. (1) (a Timoshenko beam whose bending and
  shear stiffness are raised by the pressure);
- the pseudo-rigid-body (PRB) model of eq. (2): two rigid bodies of lengths ``l1`` and ``l2``
  joined by a torsional spring of stiffness ``k``.

Equating the PRB and eq. (1) deflections at the characterization probe turns the measured
stiffness ``k`` of Table 3 into the fabric's Young's modulus ``E``.
"""

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import brentq

__all__ = [
    'LINK_LENGTH',
    'LINK_RADIUS',
    'MEAN_STIFFNESS',
    'PAPER_POISSON_RATIO',
    'PROBE_DISTANCE',
    'SHEAR_COEFFICIENT',
    'SPRING_OFFSET',
    'TABLE3',
    'TAU_MAX_LINK1',
    'TESTED_PRESSURES',
    'WALL_THICKNESS',
    'Table3Row',
    'TubeSection',
    'cap_force',
    'inflatable_beam_deflection',
    'lowest_sufficient_pressure',
    'min_pressure_for_moment',
    'prb_probe_deflection',
    'stiffness_from_young_modulus',
    'tube_area',
    'tube_second_moment',
    'wrinkling_moment',
    'young_modulus_from_stiffness',
]

# Prototype geometry, section 3 of 000_ce37cf035a0a87c6.
LINK_LENGTH = 0.600  # L [m]
LINK_RADIUS = 0.055  # r [m]
WALL_THICKNESS = 0.5e-3  # t [m]
# Characterization set-up, section 4: probe distance h and the first wrinkle (PRB hinge) l1.
PROBE_DISTANCE = 0.500  # h [m]
SPRING_OFFSET = 0.030  # l1 [m]
# Shear correction j for thin circular tubes, section 2.1.
SHEAR_COEFFICIENT = 0.5
# Effective Poisson ratio that, through G = E / (2 (1 + nu)), reproduces the paper's
# E = 136-140 MPa from k̄ (see young_modulus_from_stiffness and the README). Above the isotropic
# limit 0.5 on purpose: it encodes the low in-plane shear modulus of a woven coated fabric
# (G / E = 0.28); an isotropic nu = 0.3 gives E about 3 % lower (132.0-135.7 MPa).
PAPER_POISSON_RATIO = 0.8
# Largest moment on link 1 during the simulated trajectory, section 5 [N·m].
TAU_MAX_LINK1 = 17.51
# Mean of the k column of Table 3, section 4 [N·m/rad].
MEAN_STIFFNESS = 172.71


@dataclass(frozen=True)
class Table3Row:
    """One row of Table 3 of 000_ce37cf035a0a87c6, in SI units.

    Attributes
    ----------
    pressure : float
        Inflation pressure p [Pa].
    stiffness : float
        PRB spring stiffness k [N·m/rad].
    stiffness_std : float
        Standard deviation sigma_k of k [N·m/rad].
    max_moment : float or None
        Mean measured torque above the wrinkling moment, M_max [N·m]; None where the paper
        reports N/A (no sample above M_w).
    wrinkling_moment : float
        Theoretical wrinkling moment M_w of eq. (3) as printed [N·m].
    """

    pressure: float
    stiffness: float
    stiffness_std: float
    max_moment: float | None
    wrinkling_moment: float


TABLE3: tuple[Table3Row, ...] = (
    Table3Row(10e3, 182.56, 3.37, 4.99, 4.11),
    Table3Row(20e3, 187.30, 1.48, 9.45, 8.21),
    Table3Row(30e3, 155.89, 2.66, 14.99, 12.32),
    Table3Row(40e3, 174.42, 6.22, 18.77, 16.42),
    Table3Row(50e3, 169.44, 5.51, 21.76, 20.53),
    Table3Row(60e3, 166.66, 4.99, None, 24.63),
)
TESTED_PRESSURES: tuple[float, ...] = tuple(row.pressure for row in TABLE3)


def _positive(name: str, value: npt.ArrayLike, unit: str) -> npt.NDArray[np.float64]:
    """Coerce ``value`` to a float array and require every element positive and finite."""
    arr = np.asarray(value, dtype=float)
    _require(name, arr, np.isfinite(arr) & (arr > 0.0), 'positive and finite', unit)
    return arr


def _non_negative(name: str, value: npt.ArrayLike, unit: str) -> npt.NDArray[np.float64]:
    """Coerce ``value`` to a float array and require every element >= 0 and finite."""
    arr = np.asarray(value, dtype=float)
    _require(name, arr, np.isfinite(arr) & (arr >= 0.0), 'non-negative and finite', unit)
    return arr


def _finite(name: str, value: npt.ArrayLike, unit: str) -> npt.NDArray[np.float64]:
    arr = np.asarray(value, dtype=float)
    _require(name, arr, np.isfinite(arr), 'finite', unit)
    return arr


def _require(name: str, arr: npt.NDArray[np.float64], ok: npt.NDArray[np.bool_], what: str,
             unit: str) -> None:
    """Raise a ValueError naming ``name`` and its first offending element unless all ``ok``."""
    if np.all(ok):
        return
    unit = f' {unit}' if unit else ''
    if arr.ndim == 0:
        raise ValueError(f'{name} must be {what}, got {float(arr)!r}{unit}')
    index = tuple(int(i) for i in np.argwhere(~ok)[0])
    raise ValueError(f'{name} must be {what}, got {float(arr[index])!r}{unit} at index '
                     f'{index if len(index) > 1 else index[0]}')


def _scalar(name: str, arr: npt.NDArray[np.float64]) -> float:
    if arr.ndim != 0:
        raise ValueError(f'expected {name} as a scalar, got shape {arr.shape}')
    return float(arr)


def _broadcast(**arrays: npt.NDArray[np.float64]) -> list[npt.NDArray[np.float64]]:
    try:
        return list(np.broadcast_arrays(*arrays.values()))
    except ValueError:
        shapes = ', '.join(f'{name} {arr.shape}' for name, arr in arrays.items())
        raise ValueError(f'expected broadcastable shapes, got {shapes}') from None


def wrinkling_moment(
    pressure: npt.ArrayLike, radius: npt.ArrayLike
) -> float | npt.NDArray[np.float64]:
    """Bending moment at which the first wrinkle appears, eq. (3) of 000_ce37cf035a0a87c6.

    ``M_w = (pi / 4) * pi * p * r**3`` (Wielgosz et al.). Beyond it the link no longer carries
    more moment, so the PRB model of eq. (2) is valid only for torques below ``M_w``.

    Parameters
    ----------
    pressure : float or array-like
        Inflation (gauge) pressure p [Pa], positive.
    radius : float or array-like, broadcastable with ``pressure``
        Tube radius r [m], positive.

    Returns
    -------
    float or ndarray
        Wrinkling moment M_w [N·m], the broadcast shape of the inputs.

    Raises
    ------
    ValueError
        If a pressure or radius is not positive and finite, or the shapes do not broadcast.
    """
    p = _positive('pressure', pressure, 'Pa')
    r = _positive('radius', radius, 'm')
    p, r = _broadcast(pressure=p, radius=r)
    return math.pi / 4.0 * math.pi * p * r**3


def min_pressure_for_moment(
    moment: npt.ArrayLike, radius: npt.ArrayLike
) -> float | npt.NDArray[np.float64]:
    """Smallest pressure whose wrinkling moment reaches ``moment``; inverse of eq. (3).

    ``p = 4 M / (pi**2 r**3)`` from eq. (3) of 000_ce37cf035a0a87c6.

    Parameters
    ----------
    moment : float or array-like
        Bending moment the link must carry without wrinkling [N·m], >= 0.
    radius : float or array-like, broadcastable with ``moment``
        Tube radius r [m], positive.

    Returns
    -------
    float or ndarray
        Minimum inflation pressure [Pa], the broadcast shape of the inputs.

    Raises
    ------
    ValueError
        If a moment is negative or not finite, a radius not positive and finite, or the shapes
        do not broadcast.
    """
    m = _non_negative('moment', moment, 'N·m')
    r = _positive('radius', radius, 'm')
    m, r = _broadcast(moment=m, radius=r)
    return 4.0 * m / (math.pi**2 * r**3)


def lowest_sufficient_pressure(
    moment: float, radius: float, pressures: npt.ArrayLike
) -> float | None:
    """Lowest of the candidate pressures whose wrinkling moment holds ``moment``.

    Applies eq. (3) of 000_ce37cf035a0a87c6 the way section 5 does: with tau_max = 17.51 N·m on
    link 1, 50 kPa is the lowest pressure of Table 3 that keeps the link below wrinkling.

    Parameters
    ----------
    moment : float
        Largest bending moment on the link [N·m], >= 0.
    radius : float
        Tube radius r [m], positive.
    pressures : array-like, shape (n,)
        Candidate inflation pressures [Pa], positive, any order, n >= 1.

    Returns
    -------
    float or None
        The smallest candidate p with ``M_w(p, r) >= moment`` [Pa], or None when no candidate
        is high enough.

    Raises
    ------
    ValueError
        If ``moment`` or ``radius`` is not a valid scalar, or ``pressures`` is not a non-empty
        1-D array of positive finite values.
    """
    m = _scalar('moment', _non_negative('moment', moment, 'N·m'))
    r = _scalar('radius', _positive('radius', radius, 'm'))
    p = np.asarray(pressures, dtype=float)
    if p.ndim != 1 or p.size == 0:
        raise ValueError(f'expected pressures of shape (n,) with n >= 1, got {p.shape}')
    p = _positive('pressures', p, 'Pa')
    enough = np.sort(p[wrinkling_moment(p, r) >= m])
    return float(enough[0]) if enough.size else None


def tube_area(radius: npt.ArrayLike, thickness: npt.ArrayLike) -> float | npt.NDArray[np.float64]:
    """Wall cross-section area of a thin-walled tube, ``S = 2 pi r t`` [m²].

    Parameters
    ----------
    radius : float or array-like
        Mid-wall radius r [m], positive.
    thickness : float or array-like, broadcastable with ``radius``
        Wall thickness t [m], positive and smaller than ``radius``.
    """
    r, t = _tube_args(radius, thickness)
    return 2.0 * math.pi * r * t


def tube_second_moment(
    radius: npt.ArrayLike, thickness: npt.ArrayLike
) -> float | npt.NDArray[np.float64]:
    """Second moment of area of a thin-walled tube about a diameter, ``I = pi r³ t`` [m⁴].

    Parameters
    ----------
    radius : float or array-like
        Mid-wall radius r [m], positive.
    thickness : float or array-like, broadcastable with ``radius``
        Wall thickness t [m], positive and smaller than ``radius``.
    """
    r, t = _tube_args(radius, thickness)
    return math.pi * r**3 * t


def _tube_args(
    radius: npt.ArrayLike, thickness: npt.ArrayLike
) -> list[npt.NDArray[np.float64]]:
    r = _positive('radius', radius, 'm')
    t = _positive('thickness', thickness, 'm')
    r, t = _broadcast(radius=r, thickness=t)
    _require('thickness', t, t < r, 'smaller than radius', 'm')
    return [r, t]


def cap_force(pressure: npt.ArrayLike, radius: npt.ArrayLike) -> float | npt.NDArray[np.float64]:
    """Axial force of the pressure on each end cap, ``P = p pi r²`` [N] (section 2.1).

    Parameters
    ----------
    pressure : float or array-like
        Inflation pressure p [Pa], >= 0.
    radius : float or array-like, broadcastable with ``pressure``
        Tube radius r [m], positive.
    """
    p = _non_negative('pressure', pressure, 'Pa')
    r = _positive('radius', radius, 'm')
    p, r = _broadcast(pressure=p, radius=r)
    return p * math.pi * r**2


@dataclass(frozen=True)
class TubeSection:
    """Thin-walled circular tube cross-section.

    Attributes
    ----------
    radius : float
        Mid-wall radius r [m].
    thickness : float
        Wall thickness t [m], 0 < t < r.
    """

    radius: float = LINK_RADIUS
    thickness: float = WALL_THICKNESS

    def __post_init__(self) -> None:
        r, t = _tube_args(self.radius, self.thickness)
        object.__setattr__(self, 'radius', _scalar('radius', r))
        object.__setattr__(self, 'thickness', _scalar('thickness', t))

    @property
    def area(self) -> float:
        """Wall area S = 2 pi r t [m²]."""
        return float(tube_area(self.radius, self.thickness))

    @property
    def second_moment(self) -> float:
        """Second moment of area I = pi r³ t [m⁴]."""
        return float(tube_second_moment(self.radius, self.thickness))

    def cap_force(self, pressure: npt.ArrayLike) -> float | npt.NDArray[np.float64]:
        """Cap force P = p pi r² [N] at pressure p [Pa]."""
        return cap_force(pressure, self.radius)


def inflatable_beam_deflection(
    x: npt.ArrayLike,
    force: npt.ArrayLike,
    load_distance: npt.ArrayLike,
    pressure: npt.ArrayLike,
    radius: npt.ArrayLike,
    thickness: npt.ArrayLike,
    young_modulus: npt.ArrayLike,
    shear_modulus: npt.ArrayLike,
    shear_coefficient: npt.ArrayLike = SHEAR_COEFFICIENT,
) -> float | npt.NDArray[np.float64]:
    """Deflection of an inflated cantilever tube under a tip-side force, eq. (1).

    Le van–Wielgosz inflatable Timoshenko beam, eq. (1) of 000_ce37cf035a0a87c6::

        v(x) = F / ((E + P/S) I) * (l x²/2 - x³/6) + F x / (P + j G S),   0 <= x <= l

    with ``P = p pi r²``, ``S = 2 pi r t`` and ``I = pi r³ t``. The extracted paper text prints
    ``(l x²/2 + x³/6)``; the sign here is minus, because for ``p -> 0`` and ``G -> inf`` eq. (1)
    must reduce to the Euler–Bernoulli cantilever ``F x² (3 l - x) / (6 E I)``, i.e.
    ``l x²/2 - x³/6`` (Le van and Wielgosz 2005 write it so). With the plus sign the slope at
    ``x = l`` would not vanish although the segment beyond the load carries no moment.

    Parameters
    ----------
    x : float or array-like
        Abscissa along the link from the clamp [m], 0 <= x <= ``load_distance``.
    force : float or array-like
        Shear force F, orthogonal to the link axis [N].
    load_distance : float or array-like
        Distance l of the force from the clamp [m], positive.
    pressure : float or array-like
        Inflation pressure p [Pa], >= 0 (0 gives the classical Timoshenko cantilever).
    radius, thickness : float or array-like
        Tube radius r and wall thickness t [m], 0 < t < r.
    young_modulus : float or array-like
        Fabric Young's modulus E [Pa], positive.
    shear_modulus : float or array-like
        Fabric shear modulus G [Pa], positive; ``np.inf`` drops the shear term.
    shear_coefficient : float or array-like, optional
        Shear correction j, positive; 0.5 for thin circular tubes.

    Returns
    -------
    float or ndarray
        Deflection v(x) [m], positive in the direction of F, the broadcast shape of the inputs.

    Raises
    ------
    ValueError
        If an argument is outside its range or not finite, or the shapes do not broadcast.
    """
    xs = _non_negative('x', x, 'm')
    F = _finite('force', force, 'N')
    load = _positive('load_distance', load_distance, 'm')
    p = _non_negative('pressure', pressure, 'Pa')
    r, t = _tube_args(radius, thickness)
    E = _positive('young_modulus', young_modulus, 'Pa')
    G = np.asarray(shear_modulus, dtype=float)
    _require('shear_modulus', G, G > 0.0, 'positive (inf allowed)', 'Pa')
    j = _positive('shear_coefficient', shear_coefficient, '')
    xs, F, load, p, r, t, E, G, j = _broadcast(
        x=xs, force=F, load_distance=load, pressure=p, radius=r, thickness=t, young_modulus=E,
        shear_modulus=G, shear_coefficient=j,
    )
    _require('x', xs, xs <= load, 'at most load_distance', 'm')
    P = cap_force(p, r)
    S = tube_area(r, t)
    I = tube_second_moment(r, t)  # noqa: E741 - paper notation
    bending = F / ((E + P / S) * I) * (load * xs**2 / 2.0 - xs**3 / 6.0)
    shear = F * xs / (P + j * G * S)
    return bending + shear


def prb_probe_deflection(
    force: npt.ArrayLike,
    stiffness: npt.ArrayLike,
    probe_distance: float = PROBE_DISTANCE,
    spring_offset: float = SPRING_OFFSET,
) -> float | npt.NDArray[np.float64]:
    """Deflection at the probe of the pseudo-rigid-body link, ``F (h - l1)² / k`` [m].

    The force F at distance h bends the torsional spring at l1 by tau = F (h - l1); eq. (2)
    of 000_ce37cf035a0a87c6 gives theta = tau / k and the probe moves theta (h - l1)
    (small angles).

    Parameters
    ----------
    force : float or array-like
        Force at the probe, orthogonal to the link [N].
    stiffness : float or array-like
        Spring stiffness k [N·m/rad], positive.
    probe_distance : float
        Distance h of the probe from the clamp [m], > ``spring_offset``.
    spring_offset : float
        Distance l1 of the PRB hinge from the clamp [m], >= 0.
    """
    F = _finite('force', force, 'N')
    k = _positive('stiffness', stiffness, 'N·m/rad')
    arm = _lever_arm(probe_distance, spring_offset)
    F, k = _broadcast(force=F, stiffness=k)
    return F * arm**2 / k


def _lever_arm(probe_distance: float, spring_offset: float) -> float:
    h = _scalar('probe_distance', _positive('probe_distance', probe_distance, 'm'))
    l1 = _scalar('spring_offset', _non_negative('spring_offset', spring_offset, 'm'))
    if h <= l1:
        raise ValueError(f'probe_distance must exceed spring_offset, got h={h!r} m, '
                         f'l1={l1!r} m')
    return h - l1


def _shear_modulus(young_modulus: float, poisson_ratio: float) -> float:
    return young_modulus / (2.0 * (1.0 + poisson_ratio))


def stiffness_from_young_modulus(
    young_modulus: npt.ArrayLike,
    pressure: npt.ArrayLike,
    radius: float,
    thickness: float,
    probe_distance: float,
    spring_offset: float,
    poisson_ratio: float = PAPER_POISSON_RATIO,
    shear_coefficient: float = SHEAR_COEFFICIENT,
) -> float | npt.NDArray[np.float64]:
    """PRB stiffness k that matches eq. (1) at the probe; inverse of young_modulus_from_stiffness.

    Solves ``F (h - l1)² / k = v(h)`` with v from eq. (1) of 000_ce37cf035a0a87c6 loaded at
    ``l = h``, and ``G = E / (2 (1 + nu))``.

    Parameters
    ----------
    young_modulus : float or array-like
        Fabric Young's modulus E [Pa], positive.
    pressure : float or array-like, broadcastable with ``young_modulus``
        Inflation pressure p [Pa], >= 0.
    radius, thickness : float
        Tube radius r and wall thickness t [m].
    probe_distance, spring_offset : float
        Probe distance h and PRB hinge offset l1 [m], h > l1 >= 0.
    poisson_ratio : float
        Poisson ratio nu, > -1 (see PAPER_POISSON_RATIO).
    shear_coefficient : float
        Shear correction j, positive.

    Returns
    -------
    float or ndarray
        Stiffness k [N·m/rad].
    """
    E = _positive('young_modulus', young_modulus, 'Pa')
    nu = _poisson(poisson_ratio)
    arm = _lever_arm(probe_distance, spring_offset)
    h = arm + float(spring_offset)
    v = inflatable_beam_deflection(h, 1.0, h, pressure, radius, thickness, E,
                                   _shear_modulus(E, nu), shear_coefficient)
    return arm**2 / v


def _poisson(poisson_ratio: float) -> float:
    nu = _scalar('poisson_ratio', _finite('poisson_ratio', poisson_ratio, ''))
    if nu <= -1.0:
        raise ValueError(f'poisson_ratio must be greater than -1, got {nu!r}')
    return nu


def young_modulus_from_stiffness(
    stiffness: npt.ArrayLike,
    pressure: npt.ArrayLike,
    radius: float,
    thickness: float,
    probe_distance: float,
    spring_offset: float,
    poisson_ratio: float = PAPER_POISSON_RATIO,
    shear_coefficient: float = SHEAR_COEFFICIENT,
) -> float | npt.NDArray[np.float64]:
    """Fabric Young's modulus from a measured PRB stiffness (section 4).

    Equates the PRB deflection at the probe with eq. (1) of 000_ce37cf035a0a87c6 loaded and
    evaluated at the probe (``x = l = h``)::

        F (h - l1)² / k = F h³ / (3 (E + P/S) I) + F h / (P + j G S),   G = E / (2 (1 + nu))

    F cancels. The right-hand side falls strictly from a finite value at E = 0 to 0, so the
    root in E is unique; it is found with ``scipy.optimize.brentq``.

    With the paper's geometry and k̄ = 172.71 N·m/rad this gives E = 140.0 MPa at 10 kPa down to
    135.6 MPa at 60 kPa for ``poisson_ratio = 0.8`` (the paper: 136-140 MPa); an isotropic
    nu = 0.3 gives 135.7-132.0 MPa. The difference sits entirely in the shear term: the paper's
    band needs G / E = 0.28, an in-plane shear modulus lower than an isotropic solid's, as
    expected of a woven coated fabric. Hence the default PAPER_POISSON_RATIO = 0.8, an effective
    value rather than a measured Poisson ratio.

    Parameters
    ----------
    stiffness : float or array-like
        PRB spring stiffness k [N·m/rad], positive.
    pressure : float or array-like, broadcastable with ``stiffness``
        Inflation pressure p [Pa], >= 0.
    radius, thickness : float
        Tube radius r and wall thickness t [m], 0 < t < r (paper: 0.055, 0.0005).
    probe_distance, spring_offset : float
        Probe distance h and PRB hinge offset l1 [m], h > l1 >= 0 (paper: 0.5, 0.03).
    poisson_ratio : float, optional
        Poisson ratio nu used for G = E / (2 (1 + nu)), > -1.
    shear_coefficient : float, optional
        Shear correction j, positive; 0.5 for thin circular tubes.

    Returns
    -------
    float or ndarray
        Young's modulus E [Pa], the broadcast shape of ``stiffness`` and ``pressure``.

    Raises
    ------
    ValueError
        If an argument is out of range, or k is so low that even E -> 0 is too stiff (the
        pressure alone, through P/S and P, already makes the link stiffer than k).
    """
    k = _positive('stiffness', stiffness, 'N·m/rad')
    p = _non_negative('pressure', pressure, 'Pa')
    k, p = _broadcast(stiffness=k, pressure=p)
    section = TubeSection(radius, thickness)
    arm = _lever_arm(probe_distance, spring_offset)
    h = arm + float(spring_offset)
    nu = _poisson(poisson_ratio)
    j = _scalar('shear_coefficient', _positive('shear_coefficient', shear_coefficient, ''))
    S, I = section.area, section.second_moment  # noqa: E741 - paper notation

    def solve(k_i: float, p_i: float) -> float:
        P = p_i * math.pi * section.radius**2
        target = arm**2 / k_i  # PRB compliance at the probe [m/N]

        def residual(E: float) -> float:
            bending = h**3 / (3.0 * (E + P / S) * I)
            shear = h / (P + j * _shear_modulus(E, nu) * S)
            return bending + shear - target

        if P > 0.0 and residual(0.0) <= 0.0:
            raise ValueError(f'stiffness {k_i!r} N·m/rad is below what pressure {p_i!r} Pa '
                             'alone gives; no positive Young modulus matches it')
        # residual falls strictly with E: widen a bracket around the sign change.
        lower = upper = 1e8
        while residual(upper) > 0.0:
            upper *= 10.0
        while residual(lower) <= 0.0:
            lower /= 10.0
        return brentq(residual, lower, upper, xtol=1e-9, rtol=1e-14)

    out = np.array([solve(float(k_i), float(p_i))
                    for k_i, p_i in zip(k.ravel(), p.ravel(), strict=True)])
    out = out.reshape(k.shape)
    return out[()] if out.ndim == 0 else out
