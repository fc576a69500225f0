"""System identification of the simulated soft arm (`inflarm_hw.sra_plant`) from a recording.

A recording holds what a run of the arm leaves on its topics: the valve set pressures that were
commanded (``chamber_pressure_command``), the chamber pressures measured
(``chamber_pressures``) and the end point measured (``ball_position`` or ``end_point_truth``),
each with its time. `identify_plant` fits chosen constants of `SoftArmPlantParams` (by default
`IDENTIFIED_FIELDS`: the valve delay, the chambers' time constants, the walls' moduli and creep
times) by weighted nonlinear least squares (``scipy.optimize.least_squares``): the plant itself
(`SoftArmPlant.step`, the one simulation) is run from rest on the recorded commands, and its
chamber pressures and end point at the recorded sample times are compared with the measured
ones. The parameters' standard errors come from the Jacobian at the optimum
(``cov = s^2 (J^T J)^-1``, ``s^2`` the residual variance).

Not identified: the valves' dead zone (`inflarm_hw.valve.ValveModel.dead_zone`) changes the
simulation only where it crosses a recorded command, so the residual is piecewise constant in
it and has no gradient to follow; it stays the initial plant's. The same holds for the
geometry (lengths, lever, stroke limit), which a recording of small motions does not separate
from the moduli. Pure numpy/scipy, no rclpy.
"""

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from inflarm_hw.sra_plant import SoftArmPlant, SoftArmPlantParams
from inflarm_model.soft_arm import CHAMBERS

__all__ = ['FIT_RANGES', 'IDENTIFIED_FIELDS', 'PlantIdentification', 'PlantRecording',
           'ReplayedRecording', 'identify_plant', 'replay_recording']

IDENTIFIED_FIELDS = ('valve_delay', 'pea_time_constant', 'bellows_time_constant',
                     'pea_modulus', 'bellows_modulus', 'pea_creep_time', 'bellows_creep_time')
"""The `SoftArmPlantParams` fields `identify_plant` fits unless told otherwise."""

FIT_RANGES = {
    'valve_delay': (0.0, 2.0),
    'pea_time_constant': (0.01, 30.0),
    'bellows_time_constant': (0.01, 30.0),
    'pea_modulus': (1e3, 1e7),
    'bellows_modulus': (1e3, 1e7),
    'pea_creep_time': (0.01, 30.0),
    'bellows_creep_time': (0.01, 30.0),
}
"""Bounds of the search per fittable field, in the field's unit (s or Pa): physical ranges wide
around the defaults, so that the optimizer never steps into a plant that cannot exist."""

_N_CHAMBERS = len(CHAMBERS)


def _samples(name: str, times: npt.ArrayLike, values: npt.ArrayLike,
             width: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    t = np.asarray(times, dtype=float)
    v = np.asarray(values, dtype=float)
    if t.ndim != 1 or v.shape != (t.size, width):
        raise ValueError(f'expected {name} times of shape (k,) and values of shape (k, {width}),'
                         f' got {t.shape} and {v.shape}')
    if not np.isfinite(t).all():
        raise ValueError(f'expected finite {name} times [s]')
    bad = np.flatnonzero(~np.isfinite(v).all(axis=1))
    if bad.size:
        raise ValueError(f'{name}: {bad.size} samples hold NaN or an infinity (first at '
                         f't = {t[bad[0]]:.3f} s)')
    if np.any(np.diff(t) < 0.0):
        raise ValueError(f'expected {name} times in increasing order')
    return t, v


@dataclass(frozen=True)
class PlantRecording:
    """A run of the soft arm: commands in, measurements out, on one time axis.

    Attributes
    ----------
    command_times : ndarray, shape (k,)
        When each valve command was given [s], increasing. Before the first, every valve is
        commanded 0 Pa (the arm at rest, as ``sra_sim`` starts).
    commands : ndarray, shape (k, 5)
        Valve set pressures in `CHAMBERS` order [Pa], each held until the next.
    pressure_times : ndarray, shape (m,)
        Times of the chamber pressure measurements [s], increasing.
    pressures : ndarray, shape (m, 5)
        Measured chamber pressures in `CHAMBERS` order [Pa].
    position_times : ndarray, shape (q,)
        Times of the end point measurements [s], increasing.
    positions : ndarray, shape (q, 3)
        Measured end point in ``sra_mount`` [m].

    The arm is taken to be at rest (every chamber at 0 Pa, walls relaxed) at the earliest of the
    times. Raises ``ValueError`` on wrong shapes, unordered times, or NaN (naming the series).
    """

    command_times: npt.NDArray[np.float64]
    commands: npt.NDArray[np.float64]
    pressure_times: npt.NDArray[np.float64]
    pressures: npt.NDArray[np.float64]
    position_times: npt.NDArray[np.float64]
    positions: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        for series, width in (('command', _N_CHAMBERS), ('pressure', _N_CHAMBERS),
                              ('position', 3)):
            t, v = _samples(f'{series}s', getattr(self, f'{series}_times'),
                            getattr(self, f'{series}s'), width)
            object.__setattr__(self, f'{series}_times', t)
            object.__setattr__(self, f'{series}s', v)

    @property
    def start_time(self) -> float:
        """Earliest time of the recording [s]: the arm is at rest here."""
        firsts = [t[0] for t in (self.command_times, self.pressure_times, self.position_times)
                  if t.size]
        return float(min(firsts)) if firsts else 0.0

    @property
    def duration(self) -> float:
        """From `start_time` to the last measurement [s]."""
        lasts = [t[-1] for t in (self.pressure_times, self.position_times) if t.size]
        return float(max(lasts)) - self.start_time if lasts else 0.0


@dataclass(frozen=True)
class ReplayedRecording:
    """What a plant does on a recording's commands, at the recording's sample times.

    pressures : ndarray, shape (m, 5), chamber pressures [Pa] at ``pressure_times``.
    positions : ndarray, shape (q, 3), true end point [m] at ``position_times``.
    """

    pressures: npt.NDArray[np.float64]
    positions: npt.NDArray[np.float64]


def replay_recording(params: SoftArmPlantParams,
                     recording: PlantRecording) -> ReplayedRecording:
    """Run the plant ``params`` from rest on the recorded commands (`SoftArmPlant.step`).

    At a time that holds both a sample and a command, the sample is taken first (a command
    acts only after the valve delay anyway).

    Parameters
    ----------
    params : SoftArmPlantParams
        The plant; its measurement noise is ignored (the true state is sampled).
    recording : PlantRecording

    Returns
    -------
    ReplayedRecording
    """
    plant = SoftArmPlant(1, replace(params, noise_center_px=0.0, noise_radius_px=0.0))
    r = recording
    times = np.unique(np.concatenate([r.command_times, r.pressure_times, r.position_times]))
    # per event: which command starts there, which samples are taken there
    command_at = np.searchsorted(times, r.command_times)
    pressure_at = np.searchsorted(times, r.pressure_times)
    position_at = np.searchsorted(times, r.position_times)
    pressures = np.empty((pressure_at.size, _N_CHAMBERS))
    positions = np.empty((position_at.size, 3))
    command = np.zeros(_N_CHAMBERS)
    next_command = next_pressure = next_position = 0
    now = times[0] if times.size else 0.0
    for event, t in enumerate(times):
        if t > now:
            plant.step(command, t - now)
            now = t
        while next_pressure < pressure_at.size and pressure_at[next_pressure] == event:
            pressures[next_pressure] = plant.chamber_pressures[0]
            next_pressure += 1
        while next_position < position_at.size and position_at[next_position] == event:
            positions[next_position] = plant.end_point[0]
            next_position += 1
        while next_command < command_at.size and command_at[next_command] == event:
            command = r.commands[next_command]
            next_command += 1
    return ReplayedRecording(pressures, positions)


@dataclass(frozen=True)
class PlantIdentification:
    """The outcome of `identify_plant`.

    Attributes
    ----------
    params : SoftArmPlantParams
        The identified plant: the initial one with the fitted fields replaced.
    fields : tuple of str
        The fitted `SoftArmPlantParams` fields.
    values, standard_errors : ndarray, shape (p,)
        Their fitted values and standard errors (Jacobian at the optimum), in the fields' units.
    pressure_rms : ndarray, shape (5,)
        RMS of measured minus replayed chamber pressure per chamber, `CHAMBERS` order [Pa].
    position_rms : ndarray, shape (3,)
        RMS of measured minus replayed end point per axis x, y, z [m].
    evaluations : int
        Evaluations of the residuals the optimizer took, each a replay of the recording (the
        finite-difference Jacobians, one replay per fitted field each, not counted).
    converged : bool
        Whether the optimizer met a tolerance (rather than its evaluation budget).
    message : str
        The optimizer's account of how it stopped.
    """

    params: SoftArmPlantParams
    fields: tuple[str, ...]
    values: npt.NDArray[np.float64]
    standard_errors: npt.NDArray[np.float64]
    pressure_rms: npt.NDArray[np.float64]
    position_rms: npt.NDArray[np.float64]
    evaluations: int
    converged: bool
    message: str


def _rms(error: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.sqrt(np.mean(error ** 2, axis=0)) if error.size else np.zeros(error.shape[1])


def identify_plant(
    recording: PlantRecording,
    initial: SoftArmPlantParams = SoftArmPlantParams(),  # noqa: B008 (frozen, immutable)
    fields: tuple[str, ...] = IDENTIFIED_FIELDS,
    pressure_std: float = 1e3,
    position_std: float = 1e-3,
    max_evaluations: int = 200,
) -> PlantIdentification:
    """Fit ``fields`` of the plant so that it replays ``recording`` (weighted least squares).

    Minimizes ``sum ((p_sim - p) / pressure_std)^2 + sum ((x_sim - x) / position_std)^2`` over
    every pressure and end point sample, the plant replayed by `replay_recording`, within
    `FIT_RANGES`, starting from ``initial``.

    Parameters
    ----------
    recording : PlantRecording
    initial : SoftArmPlantParams
        Start of the search, and the values of every field not fitted.
    fields : tuple of str
        Fields to fit, each a key of `FIT_RANGES`.
    pressure_std, position_std : float
        Expected measurement error of a pressure [Pa] and of an end point coordinate [m]: the
        weights that make the two kinds of residual comparable, > 0.
    max_evaluations : int
        Budget of residual evaluations (`PlantIdentification.evaluations`), >= 1.

    Returns
    -------
    PlantIdentification

    Raises
    ------
    ValueError
        On an unknown field, bad weights, or a recording without pressure or end point samples.
    """
    unknown = [f for f in fields if f not in FIT_RANGES]
    if unknown or not fields:
        raise ValueError(f'expected fields among {sorted(FIT_RANGES)}, got {list(fields)}')
    if not (pressure_std > 0.0 and position_std > 0.0):
        raise ValueError(f'expected pressure_std, position_std > 0, got {pressure_std}, '
                         f'{position_std}')
    if recording.pressures.size == 0 or recording.positions.size == 0:
        raise ValueError('expected a recording with chamber pressure and end point samples')
    fields = tuple(fields)
    low = np.array([FIT_RANGES[f][0] for f in fields])
    high = np.array([FIT_RANGES[f][1] for f in fields])
    start = np.array([getattr(initial, f) for f in fields], dtype=float)
    # search in units of a typical value (the start, or a tenth of the range when it is 0)
    # so that every coordinate is of order 1 for the optimizer's steps
    scale = np.where(start > 0.0, start, 0.1 * high)
    x0 = np.clip(start, low + 1e-6 * scale, high - 1e-6 * scale) / scale

    def plant(x: npt.NDArray[np.float64]) -> SoftArmPlantParams:
        return replace(initial, **dict(zip(fields, (x * scale).tolist(), strict=True)))

    def residuals(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        replayed = replay_recording(plant(x), recording)
        return np.concatenate([
            ((replayed.pressures - recording.pressures) / pressure_std).ravel(),
            ((replayed.positions - recording.positions) / position_std).ravel()])

    # diff_step: relative steps of 1e-4 stay above the play operator's and the delay line's
    # kinks in the replay, which smaller steps would see as noise in the Jacobian
    fit = least_squares(residuals, x0, bounds=(low / scale, high / scale), diff_step=1e-4,
                        x_scale='jac', max_nfev=max_evaluations)
    params = plant(fit.x)
    dof = max(fit.fun.size - fit.x.size, 1)
    variance = 2.0 * fit.cost / dof
    jac = fit.jac * (1.0 / scale)  # d residual / d value
    covariance = variance * np.linalg.pinv(jac.T @ jac)
    replayed = replay_recording(params, recording)
    return PlantIdentification(
        params=params, fields=fields, values=fit.x * scale,
        standard_errors=np.sqrt(np.maximum(np.diag(covariance), 0.0)),
        pressure_rms=_rms(replayed.pressures - recording.pressures),
        position_rms=_rms(replayed.positions - recording.positions),
        evaluations=int(fit.nfev), converged=bool(fit.status > 0), message=str(fit.message))
