"""Static characterization of the inflatable link: cantilever samples to Table 3 and Fig 9.

Pure numpy core (no ROS); matplotlib is imported only inside :func:`plot_characteristic`.
Sections 3-4 of 000_ce37cf035a0a87c6: the link is clamped as a cantilever, a UR5 pushes a probe at
distance h from the clamp by v_UR orthogonally to the rest axis and a force sensor reads F, at a
set of constant inflation pressures. Per pressure, the pseudo-rigid-body (PRB) stiffness k of
eq. (2) is fitted on the samples below the wrinkling moment M_w of eq. (3), and the mean torque of
the samples above it gives the saturation torque M_max.

Samples CSV format (one header line, then one sample per line, SI units)::

    pressure_pa,displacement_m,force_n,probe_distance_m,spring_offset_m
    10000.0,0.0012,0.98,0.5,0.03
"""

from collections.abc import Callable, Iterable, Sequence
import csv
from dataclasses import dataclass
import io
import math
import os

import numpy as np
import numpy.typing as npt

from inflarm_model.link import (
    LINK_RADIUS,
    PROBE_DISTANCE,
    SPRING_OFFSET,
    TABLE3,
    Table3Row,
    wrinkling_moment,
)

__all__ = [
    'SAMPLES_HEADER',
    'TABLE3_CSV_HEADER',
    'CantileverSamples',
    'PressureFit',
    'SamplesFormatError',
    'angle_and_torque',
    'characterize',
    'fit_pressure',
    'plot_characteristic',
    'read_samples_csv',
    'synthetic_samples',
    'table3_csv',
    'table3_markdown',
    'write_samples_csv',
]

SAMPLES_HEADER: tuple[str, ...] = (
    'pressure_pa', 'displacement_m', 'force_n', 'probe_distance_m', 'spring_offset_m',
)
TABLE3_CSV_HEADER: tuple[str, ...] = (
    'pressure_pa', 'stiffness_nm_per_rad', 'stiffness_std_nm_per_rad', 'max_moment_nm',
    'wrinkling_moment_nm', 'n_linear', 'n_saturated',
)
# Set-point pressures are grouped to this resolution, so sensor jitter (10012 Pa) still lands in
# the 10 kPa test [Pa].
DEFAULT_PRESSURE_STEP = 1000.0


class SamplesFormatError(ValueError):
    """A samples CSV file is malformed; the message names the file, line and column."""

    def __init__(self, path: str, line: int, column: str | None, problem: str) -> None:
        where = f'{path}:{line}' + (f': column {column!r}' if column else '')
        super().__init__(f'{where}: {problem}')
        self.path = path
        self.line = line
        self.column = column


@dataclass(frozen=True, eq=False)
class CantileverSamples:
    """Raw cantilever samples, one element per measurement (section 3 of 000_ce37cf035a0a87c6).

    Attributes
    ----------
    pressure : ndarray, shape (n,)
        Inflation pressure p during the sample [Pa], positive.
    displacement : ndarray, shape (n,)
        Probe displacement v_UR imposed by the UR5, orthogonal to the rest axis [m].
    force : ndarray, shape (n,)
        Force F measured at the probe, orthogonal to the rest axis [N].
    probe_distance : ndarray, shape (n,)
        Distance h of the probe from the clamp [m].
    spring_offset : ndarray, shape (n,)
        Distance l1 of the first wrinkle (PRB hinge) from the clamp [m], 0 <= l1 < h.
    """

    pressure: npt.NDArray[np.float64]
    displacement: npt.NDArray[np.float64]
    force: npt.NDArray[np.float64]
    probe_distance: npt.NDArray[np.float64]
    spring_offset: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        arrays = {name: np.asarray(getattr(self, name), dtype=float) for name in _FIELDS}
        n = arrays['pressure'].shape
        for name, arr in arrays.items():
            if arr.ndim != 1 or arr.shape != n or arr.size == 0:
                raise ValueError(f'expected {name} of shape (n,) with n >= 1 like pressure '
                                 f'{n}, got {arr.shape}')
            if not np.all(np.isfinite(arr)):
                raise ValueError(f'{name} must be finite, got {arr[~np.isfinite(arr)][0]!r} '
                                 f'at index {int(np.argmin(np.isfinite(arr)))}')
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        _check_sample_ranges(arrays)

    def __len__(self) -> int:
        return int(self.pressure.size)


_FIELDS = ('pressure', 'displacement', 'force', 'probe_distance', 'spring_offset')


def _check_sample_ranges(arrays: dict[str, npt.NDArray[np.float64]]) -> None:
    checks = (
        ('pressure', arrays['pressure'] > 0.0, 'positive', 'Pa'),
        ('spring_offset', arrays['spring_offset'] >= 0.0, 'non-negative', 'm'),
        ('probe_distance', arrays['probe_distance'] > arrays['spring_offset'],
         'greater than spring_offset', 'm'),
    )
    for name, ok, what, unit in checks:
        if not np.all(ok):
            i = int(np.argmin(ok))
            raise ValueError(f'{name} must be {what}, got {arrays[name][i]!r} {unit} '
                             f'at index {i}')


def angle_and_torque(
    displacement: npt.ArrayLike,
    force: npt.ArrayLike,
    probe_distance: npt.ArrayLike = PROBE_DISTANCE,
    spring_offset: npt.ArrayLike = SPRING_OFFSET,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """PRB spring angle and torque from one cantilever sample, small-angle approximation.

    In the PRB model of 000_ce37cf035a0a87c6 (Fig 2) the body of length l1 stays with the clamp
    and the rest of the link turns rigidly about the hinge at l1. The probe at h moves v_UR
    orthogonally to the rest axis, so ``tan(theta) = v_UR / (h - l1)``; the measured force F is
    orthogonal to the rest axis, so its arm about the hinge is ``(h - l1) cos(theta)``. For small
    angles (section 4)::

        theta = v_UR / (h - l1),    tau = F (h - l1)

    Parameters
    ----------
    displacement : float or array-like
        Probe displacement v_UR [m].
    force : float or array-like, broadcastable with ``displacement``
        Measured probe force F [N].
    probe_distance : float or array-like
        Probe distance h from the clamp [m].
    spring_offset : float or array-like
        PRB hinge distance l1 from the clamp [m], 0 <= l1 < h.

    Returns
    -------
    angle : ndarray
        Spring deflection theta [rad].
    torque : ndarray
        Spring reaction torque tau [N·m].

    Raises
    ------
    ValueError
        If an input is not finite, l1 < 0, h <= l1, or the shapes do not broadcast.
    """
    named = {'displacement': displacement, 'force': force, 'probe_distance': probe_distance,
             'spring_offset': spring_offset}
    arrays = {}
    for name, value in named.items():
        arr = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f'{name} must be finite, got {value!r}')
        arrays[name] = arr
    try:
        v, F, h, l1 = np.broadcast_arrays(*arrays.values())
    except ValueError:
        shapes = ', '.join(f'{k} {a.shape}' for k, a in arrays.items())
        raise ValueError(f'expected broadcastable shapes, got {shapes}') from None
    if np.any(l1 < 0.0):
        raise ValueError(f'spring_offset must be non-negative, got {np.min(l1)!r} m')
    if np.any(h <= l1):
        raise ValueError('probe_distance must be greater than spring_offset')
    arm = h - l1
    return v / arm, F * arm


@dataclass(frozen=True)
class PressureFit:
    """Characterization of the link at one pressure: a row of Table 3 of 000_ce37cf035a0a87c6.

    Attributes
    ----------
    pressure : float
        Inflation pressure p [Pa].
    stiffness : float
        PRB spring stiffness k [N·m/rad], least-squares slope through the origin.
    stiffness_std : float
        Standard error sigma_k of the slope [N·m/rad].
    max_moment : float or None
        Mean |tau| of the samples at or above M_w, the saturation torque M_max [N·m]; None when
        no sample reached M_w.
    wrinkling_moment : float
        M_w of eq. (3) at ``pressure`` [N·m].
    n_linear : int
        Number of samples below M_w (used for k).
    n_saturated : int
        Number of samples at or above M_w (used for M_max).
    """

    pressure: float
    stiffness: float
    stiffness_std: float
    max_moment: float | None
    wrinkling_moment: float
    n_linear: int
    n_saturated: int

    def torque(self, angle: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Bilinear characteristic: ``k theta`` up to ``M_max``, then flat (Fig 9).

        Parameters
        ----------
        angle : float or array-like
            Spring deflection theta [rad].

        Returns
        -------
        ndarray
            Torque [N·m], odd in theta; purely linear when ``max_moment`` is None.
        """
        theta = np.asarray(angle, dtype=float)
        if not np.all(np.isfinite(theta)):
            raise ValueError(f'angle must be finite, got {angle!r}')
        linear = self.stiffness * theta
        if self.max_moment is None:
            return linear
        return np.clip(linear, -self.max_moment, self.max_moment)


def fit_pressure(
    angle: npt.ArrayLike,
    torque: npt.ArrayLike,
    pressure: float,
    radius: float = LINK_RADIUS,
) -> PressureFit:
    """Fit the PRB stiffness and saturation torque at one pressure (section 4).

    Samples with ``|tau| < M_w`` (eq. (3) of 000_ce37cf035a0a87c6) follow eq. (2),
    ``tau = k theta``. k is their least-squares slope *through the origin* (the rest position is
    the zero of both theta and tau, so an intercept would only absorb noise):
    ``k = sum(theta tau) / sum(theta²)``, with the standard error
    ``sigma_k = sqrt(sum((tau - k theta)²) / (n - 1) / sum(theta²))``. M_max is the mean |tau| of
    the remaining samples.

    Parameters
    ----------
    angle : array-like, shape (n,)
        Spring deflections theta [rad].
    torque : array-like, shape (n,)
        Spring torques tau [N·m].
    pressure : float
        Inflation pressure p [Pa], positive.
    radius : float, optional
        Tube radius r [m], positive, for M_w.

    Returns
    -------
    PressureFit

    Raises
    ------
    ValueError
        On shape mismatch, non-finite values, or fewer than two samples below M_w with a
        non-zero angle.
    """
    theta = np.asarray(angle, dtype=float)
    tau = np.asarray(torque, dtype=float)
    if theta.ndim != 1 or tau.shape != theta.shape:
        raise ValueError(f'expected angle and torque of the same shape (n,), got {theta.shape} '
                         f'and {tau.shape}')
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(tau))):
        raise ValueError('angle and torque must be finite')
    m_w = float(wrinkling_moment(pressure, radius))
    below = np.abs(tau) < m_w
    x, y = theta[below], tau[below]
    sxx = float(np.sum(x * x))
    if x.size < 2 or sxx == 0.0:
        raise ValueError(f'at pressure {pressure!r} Pa, need at least 2 samples with |torque| '
                         f'below M_w = {m_w:.3f} N·m and a non-zero angle, got {x.size}')
    k = float(np.sum(x * y)) / sxx
    residual = y - k * x
    sigma_k = math.sqrt(float(np.sum(residual**2)) / (x.size - 1) / sxx)
    above = np.abs(tau[~below])
    m_max = float(np.mean(above)) if above.size else None
    return PressureFit(float(pressure), k, sigma_k, m_max, m_w, int(x.size), int(above.size))


def _group_keys(
    pressure: npt.NDArray[np.float64], pressure_step: float
) -> npt.NDArray[np.float64]:
    step = float(pressure_step)
    if not (math.isfinite(step) and step > 0.0):
        raise ValueError(f'pressure_step must be positive and finite, got {pressure_step!r} Pa')
    keys = np.round(pressure / step) * step
    if np.any(keys <= 0.0):
        raise ValueError(f'pressure_step {step!r} Pa rounds pressure '
                         f'{float(pressure[keys <= 0.0][0])!r} Pa to zero; use a smaller step')
    return keys


def characterize(
    samples: CantileverSamples,
    radius: float = LINK_RADIUS,
    pressure_step: float = DEFAULT_PRESSURE_STEP,
) -> tuple[PressureFit, ...]:
    """Table 3 of 000_ce37cf035a0a87c6 from raw cantilever samples.

    Converts each sample with :func:`angle_and_torque`, groups the samples by pressure (rounded
    to ``pressure_step``) and fits each group with :func:`fit_pressure`.

    Parameters
    ----------
    samples : CantileverSamples
        Raw samples, any number of pressures.
    radius : float, optional
        Tube radius r [m] for the wrinkling moment.
    pressure_step : float, optional
        Resolution of the set-point pressures [Pa]; the reported pressure is the rounded one.

    Returns
    -------
    tuple of PressureFit
        One fit per pressure, by increasing pressure.
    """
    if not isinstance(samples, CantileverSamples):
        raise ValueError(f'expected samples as CantileverSamples, got {type(samples).__name__}')
    theta, tau = angle_and_torque(samples.displacement, samples.force, samples.probe_distance,
                                  samples.spring_offset)
    keys = _group_keys(samples.pressure, pressure_step)
    return tuple(fit_pressure(theta[keys == p], tau[keys == p], float(p), radius)
                 for p in np.unique(keys))


def _fmt(value: float | None, digits: int) -> str:
    return '' if value is None else f'{value:.{digits}f}'


def table3_csv(fits: Iterable[PressureFit]) -> str:
    """Table 3 as CSV text in SI units, header :data:`TABLE3_CSV_HEADER`.

    ``max_moment_nm`` is empty where M_max is None (the paper's N/A).
    """
    out = io.StringIO()
    writer = csv.writer(out, lineterminator='\n')
    writer.writerow(TABLE3_CSV_HEADER)
    for f in fits:
        writer.writerow([repr(f.pressure), repr(f.stiffness), repr(f.stiffness_std),
                         '' if f.max_moment is None else repr(f.max_moment),
                         repr(f.wrinkling_moment), f.n_linear, f.n_saturated])
    return out.getvalue()


def table3_markdown(fits: Iterable[PressureFit | Table3Row]) -> str:
    """Table 3 as a Markdown table in the paper's units (kPa, N·m/rad, N·m), two decimals.

    Accepts fitted rows or the paper's :data:`inflarm_model.link.TABLE3` rows.
    """
    lines = ['| p [kPa] | k [N·m/rad] | σ_k [N·m/rad] | M_max [N·m] | M_w [N·m] |',
             '|--:|--:|--:|--:|--:|']
    for f in fits:
        m_max = 'N/A' if f.max_moment is None else _fmt(f.max_moment, 2)
        lines.append(f'| {f.pressure / 1e3:g} | {f.stiffness:.2f} | {f.stiffness_std:.2f} | '
                     f'{m_max} | {f.wrinkling_moment:.2f} |')
    return '\n'.join(lines) + '\n'


def read_samples_csv(path: str | os.PathLike[str]) -> CantileverSamples:
    """Read a samples CSV file (header :data:`SAMPLES_HEADER`, columns in any order).

    Blank lines are skipped. Every value must be a finite number; pressure positive,
    spring offset non-negative and probe distance greater than spring offset.

    Parameters
    ----------
    path : str or os.PathLike
        File to read (UTF-8, an Excel byte-order mark is accepted).

    Returns
    -------
    CantileverSamples

    Raises
    ------
    SamplesFormatError
        On a missing or wrong header, a row with the wrong number of fields, a bad value
        (message ``FILE:LINE: column 'NAME': ...``), or no data rows.
    OSError
        If the file cannot be opened.
    """
    name = os.fspath(path)
    with open(name, newline='', encoding='utf-8-sig') as handle:
        reader = csv.reader(handle)
        header = None
        for row in reader:
            if any(cell.strip() for cell in row):
                header = [cell.strip() for cell in row]
                break
        if header is None:
            raise SamplesFormatError(name, max(reader.line_num, 1), None,
                                     f'empty file, expected the header {",".join(SAMPLES_HEADER)}')
        if sorted(header) != sorted(SAMPLES_HEADER):
            raise SamplesFormatError(name, reader.line_num, None,
                                     f'expected the header {",".join(SAMPLES_HEADER)}, got '
                                     f'{",".join(header)}')
        order = [header.index(col) for col in SAMPLES_HEADER]
        values: list[list[float]] = []
        for row in reader:
            if not any(cell.strip() for cell in row):
                continue
            if len(row) != len(header):
                raise SamplesFormatError(name, reader.line_num, None,
                                         f'expected {len(header)} fields, got {len(row)}')
            values.append(_parse_row(name, reader.line_num, [row[i] for i in order]))
    if not values:
        raise SamplesFormatError(name, reader.line_num, None, 'no data rows after the header')
    columns = np.array(values, dtype=float).T
    return CantileverSamples(*columns)


def _parse_row(path: str, line: int, cells: Sequence[str]) -> list[float]:
    row = []
    for column, cell in zip(SAMPLES_HEADER, cells, strict=True):
        try:
            value = float(cell)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise SamplesFormatError(path, line, column,
                                     f'expected a finite number, got {cell!r}')
        row.append(value)
    pressure, _, _, probe, offset = row
    if pressure <= 0.0:
        raise SamplesFormatError(path, line, 'pressure_pa', f'must be positive, got {pressure!r}')
    if offset < 0.0:
        raise SamplesFormatError(path, line, 'spring_offset_m',
                                 f'must be non-negative, got {offset!r}')
    if probe <= offset:
        raise SamplesFormatError(path, line, 'probe_distance_m',
                                 f'must exceed spring_offset_m ({offset!r}), got {probe!r}')
    return row


def write_samples_csv(path: str | os.PathLike[str], samples: CantileverSamples) -> None:
    """Write samples in the CSV format read by :func:`read_samples_csv` (values round-trip)."""
    with open(os.fspath(path), 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle, lineterminator='\n')
        writer.writerow(SAMPLES_HEADER)
        for row in zip(*(getattr(samples, name) for name in _FIELDS), strict=True):
            writer.writerow([repr(float(v)) for v in row])


def synthetic_samples(
    rng: np.random.Generator,
    rows: Sequence[Table3Row] = TABLE3,
    n_linear: int = 20,
    n_saturated: int = 10,
    probe_distance: float = PROBE_DISTANCE,
    spring_offset: float = SPRING_OFFSET,
    radius: float = LINK_RADIUS,
) -> CantileverSamples:
    """Cantilever samples consistent with Table 3 of 000_ce37cf035a0a87c6 (its raw data is
    unpublished).

    Per row the true characteristic is bilinear, ``min(k theta, M_max)`` (Fig 9):

    - ``n_linear`` evenly spaced angles up to ``theta_a``, with Gaussian torque noise of standard
      deviation ``sigma_lin = sigma_k sqrt(sum(theta_i²))``: the noise whose through-origin fit
      has the row's sigma_k as standard error. ``theta_a = M_w / (k + 2 sigma_k sqrt(c))``,
      ``c = sum((i / n)²)``, keeps the top sample two noise deviations below M_w, so the split
      at M_w does not bias k;
    - ``n_saturated`` evenly spaced angles from ``1.1 M_max / k`` to ``2 M_max / k`` on the
      plateau, with noise ``min(sigma_lin, (M_max - M_w) / 3)`` (Table 3's M_max is at most
      1.2 N·m above M_w);
    - where M_max is None (60 kPa) only the linear samples.

    Noisy torques on the wrong side of M_w are redrawn, so the split at M_w matches the
    generating regime exactly. The UR5 displacement is exact and the noise sits in the measured
    force, as in the set-up of section 3.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the noise (seed it for reproducible samples).
    rows : sequence of Table3Row, optional
        Target characteristics; Table 3 by default.
    n_linear, n_saturated : int, optional
        Samples per pressure below M_w (>= 2) and on the plateau (>= 1).
    probe_distance, spring_offset : float, optional
        Set-up distances h and l1 [m], 0 <= l1 < h.
    radius : float, optional
        Tube radius r [m] for M_w.

    Returns
    -------
    CantileverSamples
        The samples of all rows, grouped by row, by increasing angle within a row.
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f'expected rng as numpy.random.Generator, got {type(rng).__name__}')
    for name, value, low in (('n_linear', n_linear, 2), ('n_saturated', n_saturated, 1)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise ValueError(f'{name} must be an integer >= {low}, got {value!r}')
    if len(rows) == 0:
        raise ValueError('expected at least one row in rows')
    arm = float(probe_distance) - float(spring_offset)
    if not (math.isfinite(arm) and arm > 0.0 and spring_offset >= 0.0):
        raise ValueError(f'expected 0 <= spring_offset < probe_distance, got '
                         f'{spring_offset!r} m and {probe_distance!r} m')
    fraction = np.arange(1, n_linear + 1) / n_linear
    spread = math.sqrt(float(np.sum(fraction**2)))
    columns: list[list[npt.NDArray[np.float64]]] = [[] for _ in _FIELDS]
    for row in rows:
        k, m_w = row.stiffness, float(wrinkling_moment(row.pressure, radius))
        theta_a = m_w / (k + 2.0 * row.stiffness_std * spread)
        theta = fraction * theta_a
        sigma_lin = row.stiffness_std * theta_a * spread
        tau = _noisy(rng, k * theta, sigma_lin, lambda t, m=m_w: np.abs(t) >= m)
        if row.max_moment is not None:
            m_max = row.max_moment
            plateau = np.linspace(1.1, 2.0, n_saturated) * m_max / k
            sigma_sat = min(sigma_lin, (m_max - m_w) / 3.0)
            tau_sat = _noisy(rng, np.full(n_saturated, m_max), sigma_sat,
                             lambda t, m=m_w: np.abs(t) < m)
            theta, tau = np.concatenate([theta, plateau]), np.concatenate([tau, tau_sat])
        n = theta.size
        for column, values in zip(columns, (
                np.full(n, row.pressure), theta * arm, tau / arm, np.full(n, probe_distance),
                np.full(n, spring_offset)), strict=True):
            column.append(values)
    return CantileverSamples(*(np.concatenate(column) for column in columns))


def _noisy(rng: np.random.Generator, mean: npt.NDArray[np.float64], sigma: float,
           rejected: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.bool_]]
           ) -> npt.NDArray[np.float64]:
    """``mean`` plus N(0, sigma) noise, redrawing the elements where ``rejected`` holds."""
    out = mean + rng.normal(0.0, sigma, mean.size)
    for _ in range(1000):
        redo = rejected(out)
        if not np.any(redo):
            return out
        out[redo] = mean[redo] + rng.normal(0.0, sigma, int(np.sum(redo)))
    raise ValueError('noise too large for the requested characteristic')


def plot_characteristic(
    samples: CantileverSamples,
    fits: Sequence[PressureFit],
    path: str | os.PathLike[str],
    pressure_step: float = DEFAULT_PRESSURE_STEP,
) -> None:
    """Save a Fig 9 style plot: torque vs angle per pressure, samples and fitted characteristic.

    Uses matplotlib's Agg canvas directly (no pyplot, no global backend change), imported here so
    that importing this module stays light.

    Parameters
    ----------
    samples : CantileverSamples
        The samples the fits came from.
    fits : sequence of PressureFit
        Output of :func:`characterize` for ``samples``.
    path : str or os.PathLike
        Output image file; the format follows the extension (``.png``).
    pressure_step : float, optional
        The grouping resolution used by :func:`characterize` [Pa].
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    theta, tau = angle_and_torque(samples.displacement, samples.force, samples.probe_distance,
                                  samples.spring_offset)
    keys = _group_keys(samples.pressure, pressure_step)
    fig = Figure(figsize=(7.0, 5.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    colors = [f'C{i % 10}' for i in range(len(fits))]
    for fit, color in zip(fits, colors, strict=True):
        mine = keys == fit.pressure
        label = f'p = {fit.pressure / 1e3:g} kPa'
        ax.plot(theta[mine], tau[mine], 'o', ms=3.5, color=color, alpha=0.7)
        end = float(np.max(np.abs(theta[mine]))) if np.any(mine) else 0.0
        if fit.max_moment is not None:
            end = max(end, fit.max_moment / fit.stiffness)
        grid = np.linspace(0.0, end, 200)
        ax.plot(grid, fit.torque(grid), '-', color=color, label=label)
    ax.set_xlabel('spring angle θ [rad]')
    ax.set_ylabel('spring torque τ [N·m]')
    ax.set_title('Inflatable link characteristic (samples and bilinear fit)')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='upper left')
    fig.tight_layout()
    fig.savefig(os.fspath(path), dpi=150)
