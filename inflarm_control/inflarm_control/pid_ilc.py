"""PID + iterative learning pressure control of the pneumatic soft arm, batched over tasks.

Section 3.1 of ``001_b59ad71c956a1751`` (Fig 6, eqs. (1), (3), (4)): three independent axis
controllers drive the end point ``(x_e, y_e, z_e)`` to the target ``(x_d, y_d, z_d)`` measured
by vision at ~5 Hz. PEA1&2 (one chamber) drives z; the quadrant of ``(x_d, y_d)`` picks which
bellows drives x and which drives y (`inflarm_model.soft_arm.QUADRANT_BELLOWS`, Fig 4). Each
axis controller computes a PID compensation ``c_k`` (eq. (1) without its ILC term) and
accumulates it into the valve output (eq. (3)) on top of the iterative-learning feedforward
``ff_k``, which is capped at ``P_set`` (eq. (4))::

    P_out^t_k = clip(ff^t_k + sum_{j <= k} c^t_j, 0, P_max),   ff^t_k = min(m^{t-1}_k, P_set)

where ``m^{t-1}`` is the memory left by the previous trial of the same task (valve outputs per
step, the first ``memory_steps`` steps; the last entry is held for the rest of the trial).
Without a memory ``ff`` is the initial output (0 kPa in the paper) and this is the paper's PID.

Learning (between trials, `PidIlcController.finish_trial`), the reading of eq. (1) that
converges (the readings are compared in ``inflarm_control/README.md``)::

    m^t_k = clip(ff^t_k + L Q[db(e^t_{k + delta})] + gamma (A^t_end - A^t_m), 0, P_set)

a phase-lead P-type update plus a share of the feedback's correction of the hold: ``e`` the
position error along the actuator's push direction, ``delta`` a lead of a few steps that undoes the
pneumatic and mechanical lag (the "various unavoidable delays" of section 3.1), ``db`` a dead
band that stops learning from errors the valves and the hysteresis cannot resolve, ``Q`` a
centred moving average, ``A^t_end - A^t_m = sum_{m < j <= end} c^t_j`` what the PID added after
the memory's last step ``m``, while its last entry was held (the steady part of the paper's
recorded output, which the slow PID reaches only after the error is gone; 0 in a trial no longer
than the memory). What it added while the arm moved is left to the error-driven term: handed on
too, it pushed the hold the way that term pulled it back, and the two settled a few millimetres
off the target. The last entry learns from the mean error of the rest of the trial. The
literal reading (the previous output added to every increment) compounds through eq. (3); the
reading "next output = previous output + this trial's accumulated PID" learns through an
integrator without lead: on the simulated arm it diverges with the default ``P_set`` and
converges, more slowly than this one, with ``P_set`` at the target's holding pressures.

Errors are taken along each actuator's push direction, ``e = s (zeta_d - zeta_e)`` with
``s = +1`` for PEA and for the bellows pushing towards ``+x``/``+y``, ``-1`` otherwise; the paper's
``e = zeta_e - zeta_d`` with positive gains would push away from the target.

Antagonistic bellows (``PidIlcParams.bellows_preload > 0``, not in the paper): instead of the
quadrant rule, each lateral axis drives its bellows pair (B4/B2 for x, B3/B1 for y) with a signed
output ``u`` (`antagonistic_pressures`): ``P_+ = P_0 + max(u, 0)``, ``P_- = P_0 + max(-u, 0)``.
With the preload ``P_0`` above the valves' dead zone (0-4 kPa) neither bellows ever exhausts, so
an axis passes through zero without the jump of a bellows leaving the dead zone (the limit cycle
near the axes of section 4.3.2), and a small correction towards an axis (the bend skew) is
possible on either side. The laws above then act on ``u`` with ``s = +1``.

Everything is vectorized over a leading axis of ``n`` tasks (arms). Pure numpy, no rclpy.
"""

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from inflarm_control.trial_metrics import TrialMetrics
from inflarm_model.soft_arm import (
    BELLOWS_PUSH,
    CHAMBER_MAX_PRESSURE,
    CHAMBERS,
    QUADRANT_BELLOWS,
    WORKSPACE_POSITIVE,
    Workspace,
    check_in_workspace,
    quadrant_of,
)

_N_CHAMBERS = len(CHAMBERS)
_PEA = CHAMBERS.index('PEA')
# (bellows pushing towards +axis, bellows pushing towards -axis) for x and y (BELLOWS_PUSH)
_PAIRS = np.array([[CHAMBERS.index(b) for b in pair] for pair in (('B4', 'B2'), ('B3', 'B1'))])


def axis_outputs(pressures: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Signed axis outputs of chamber pressures: ``(B4 - B2, B3 - B1, PEA)``.

    Parameters
    ----------
    pressures : array-like, shape (..., 5)
        Chamber pressures in `CHAMBERS` order [Pa].

    Returns
    -------
    ndarray, shape (..., 3)
        x, y: the pressure of the bellows pushing towards ``+x`` (``+y``) minus the one pushing
        towards ``-x`` (``-y``); z: the PEA pressure [Pa]. The inverse of
        `antagonistic_pressures` for any preload.
    """
    p = np.asarray(pressures, dtype=float)
    if p.ndim == 0 or p.shape[-1] != _N_CHAMBERS:
        raise ValueError(f'expected pressures of shape (..., 5), got {p.shape}')
    return np.stack([p[..., _PAIRS[0, 0]] - p[..., _PAIRS[0, 1]],
                     p[..., _PAIRS[1, 0]] - p[..., _PAIRS[1, 1]], p[..., _PEA]], axis=-1)


def antagonistic_pressures(
    outputs: npt.ArrayLike, preload: float
) -> npt.NDArray[np.float64]:
    """Chamber pressures of signed axis outputs, each bellows pair driven antagonistically.

    ``P_+ = P_0 + max(u, 0)`` for the bellows pushing towards ``+axis`` (B4 for x, B3 for y),
    ``P_- = P_0 + max(-u, 0)`` for its opposite (B2, B1), PEA = ``u_z``.

    Parameters
    ----------
    outputs : array-like, shape (..., 3)
        Signed outputs ``(u_x, u_y, u_z)`` [Pa] (`axis_outputs`).
    preload : float
        ``P_0``: pressure of both bellows of a pair at ``u = 0`` [Pa], >= 0.

    Returns
    -------
    ndarray, shape (..., 5)
        In `CHAMBERS` order [Pa].
    """
    u = np.asarray(outputs, dtype=float)
    if u.ndim == 0 or u.shape[-1] != 3:
        raise ValueError(f'expected outputs of shape (..., 3), got {u.shape}')
    if not (np.isfinite(preload) and preload >= 0.0):
        raise ValueError(f'expected preload >= 0 Pa, got {preload}')
    pressures = np.empty(u.shape[:-1] + (_N_CHAMBERS,))
    pressures[..., _PEA] = u[..., 2]
    for axis in range(2):
        pressures[..., _PAIRS[axis, 0]] = preload + np.maximum(u[..., axis], 0.0)
        pressures[..., _PAIRS[axis, 1]] = preload + np.maximum(-u[..., axis], 0.0)
    return pressures


def clip_without_windup(
    raw: npt.NDArray[np.float64], low, high, error: npt.NDArray[np.float64],
    integral: npt.NDArray[np.float64], previous_integral: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """An output clipped to ``[low, high]`` and its integral, with anti-windup by conditional
    integration: the integral keeps ``previous_integral`` where the output is pinned against a
    limit in the direction the error pushes (the path follower's PI and eq. (1) here).

    Returns
    -------
    output, integral : ndarray
    """
    output = np.minimum(np.maximum(raw, low), high)
    pinned = ((raw > high) & (error > 0.0)) | ((raw < low) & (error < 0.0))
    return output, np.where(pinned, previous_integral, integral)


@dataclass(frozen=True)
class PidIlcParams:
    """Gains and limits of the three axis controllers (x, y, z).

    Attributes
    ----------
    kp : tuple of 3 float
        ``K_P`` of eq. (1) per axis [Pa/m]. Because eq. (3) accumulates the compensation, it
        acts on the output as an integral gain of ``kp / dt`` [Pa/(m s)]. Low on purpose: the
        paper's PID alone needs >= 15 s (Fig 7) to avoid overshoot.
    ki : tuple of 3 float
        ``K_I`` of eq. (1) per axis [Pa/(m s)] (a double integral on the output).
    kd : tuple of 3 float
        ``K_D`` of eq. (1) per axis [Pa s/m] (a proportional brake on the output).
    p_set : tuple of 3 float
        ``P_set`` of eq. (4) per axis: cap on the learned feedforward [Pa]. Must exceed the
        holding pressure of every target (the PEA needs ~100 kPa at z = 0.99 m).
    p_max : tuple of 5 float
        Valve output limit per chamber in `CHAMBERS` order [Pa]; outputs are clipped to
        ``[0, p_max]`` (positive pressure only, as in the paper).
    rate_hz : float
        Nominal control rate [Hz]; ~5 Hz in the paper. One memory entry per step.
    memory_steps : int
        Steps of feedforward kept per task; 50 = the first 10 s at 5 Hz (section 3.2).
    learning : bool
        If False the memory passed to `PidIlcController.start_trial` is ignored (PID alone);
        `PidIlcController.finish_trial` still returns what this trial learned.
    learning_gain : tuple of 3 float
        ``L`` per axis [Pa/m]: feedforward change per metre of error. About a fifth of the
        arm's inverse static gain around the Fig 7 target (409, 446, 284 kPa/m): with the
        valves' delay and the walls' creep it learns the Fig 7 task in about 30 trials, as the
        paper's Fig 8 does (``README.md``).
    learning_lead_steps : tuple of 3 int
        ``delta`` per axis [steps]: error ``delta`` steps later corrects the feedforward of this
        step. 3 steps (0.6 s) for the bellows, 5 (1 s) for the large PEA chamber.
    learning_filter_steps : int
        Half-width of the centred moving average ``Q`` [steps]; 0 disables it.
    learning_dead_band : float
        Errors up to this size teach nothing [m]; larger ones teach their excess. 1 mm: below
        it the error is set by the valves' 4 kPa dead zone and the actuators' hysteresis, and
        chasing it makes the RMSE wander from trial to trial.
    learning_feedback_gain : tuple of 3 float
        ``gamma`` per axis [-]: fraction of what the PID added after the memory's last step
        (while its last entry was held) added to the whole feedforward. The slow integral-like
        PID removes steady errors before the error-driven update sees them; this hands its
        correction of the hold (the part of the paper's recorded output that is steady) to the
        next trial, in trials longer than the memory. 0.3.
    quadrant_bellows : tuple of 4 (str, str)
        Quadrant 1-4 -> (bellows driving x, bellows driving y); Fig 4 by default. The x bellows
        must be B2 or B4, the y bellows B1 or B3. Not used with a ``bellows_preload``.
    bellows_preload : float
        0 (default): the paper's quadrant rule, one bellows per axis, the others at 0 Pa.
        ``> 0``: each bellows pair is driven antagonistically around this common pressure [Pa]
        (module docstring); above the valves' 4 kPa dead zone to be useful, below every
        bellows' ``p_max``.
    workspace : Workspace
        Bounds that start and target must respect (positive pressure, Fig 5A, by default).
    """

    kp: tuple[float, float, float] = (10e3, 10e3, 3e3)
    ki: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    p_set: tuple[float, float, float] = (90e3, 90e3, 100e3)
    p_max: tuple[float, float, float, float, float] = (CHAMBER_MAX_PRESSURE,) * 5
    rate_hz: float = 5.0
    memory_steps: int = 50
    learning: bool = True
    learning_gain: tuple[float, float, float] = (90e3, 90e3, 60e3)
    learning_lead_steps: tuple[int, int, int] = (3, 3, 5)
    learning_filter_steps: int = 1
    learning_dead_band: float = 1e-3
    learning_feedback_gain: tuple[float, float, float] = (0.3, 0.3, 0.3)
    quadrant_bellows: tuple[tuple[str, str], ...] = field(
        default=tuple(QUADRANT_BELLOWS[q] for q in (1, 2, 3, 4)))
    workspace: Workspace = WORKSPACE_POSITIVE
    bellows_preload: float = 0.0

    def __post_init__(self) -> None:
        for name, size in (('kp', 3), ('ki', 3), ('kd', 3), ('p_set', 3), ('p_max', 5),
                           ('learning_gain', 3), ('learning_lead_steps', 3),
                           ('learning_feedback_gain', 3)):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (size,):
                raise ValueError(f'expected {name} of shape ({size},), got {value.shape}')
            if not np.all(np.isfinite(value)) or np.any(value < 0.0):
                raise ValueError(f'expected finite non-negative {name}, got {value}')
        if not np.all(np.asarray(self.p_max) > 0.0):
            raise ValueError(f'expected p_max > 0 Pa per chamber, got {self.p_max}')
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0.0):
            raise ValueError(f'expected rate_hz > 0, got {self.rate_hz}')
        for name in ('memory_steps', 'learning_filter_steps'):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 0 \
                    or (name == 'memory_steps' and value < 1):
                raise ValueError(f'expected {name} a non-negative integer (memory_steps >= 1), '
                                 f'got {value}')
        if any(int(d) != d for d in self.learning_lead_steps):
            raise ValueError(
                f'expected integer learning_lead_steps, got {self.learning_lead_steps}')
        if not (np.isfinite(self.learning_dead_band) and self.learning_dead_band >= 0.0):
            raise ValueError(f'expected learning_dead_band >= 0 m, got {self.learning_dead_band}')
        if not (np.isfinite(self.bellows_preload)
                and 0.0 <= self.bellows_preload < min(self.p_max[1:])):
            raise ValueError(f'expected 0 <= bellows_preload < the bellows p_max '
                             f'{min(self.p_max[1:])} Pa, got {self.bellows_preload}')
        if len(self.quadrant_bellows) != 4:
            raise ValueError(
                f'expected quadrant_bellows for 4 quadrants, got {len(self.quadrant_bellows)}')
        for q, pair in enumerate(self.quadrant_bellows, start=1):
            if len(pair) != 2 or pair[0] not in ('B2', 'B4') or pair[1] not in ('B1', 'B3'):
                raise ValueError(
                    f'expected quadrant_bellows[{q - 1}] = (x bellows in B2/B4, y bellows in '
                    f'B1/B3), got {pair}')


def _points(
    value: npt.ArrayLike, n: int, name: str, workspace: Workspace | None = None
) -> npt.NDArray[np.float64]:
    a = np.asarray(value, dtype=float)
    if a.shape not in ((3,), (n, 3)):
        raise ValueError(f'expected {name} of shape (3,) or ({n}, 3), got {a.shape}')
    if workspace is not None:
        check_in_workspace(a, workspace, name)  # before broadcasting: messages index a batch
    elif not np.isfinite(a).all():
        raise ValueError(f'expected finite {name} [m], got {a}')
    return np.broadcast_to(a, (n, 3)).copy()


def _moving_average(a: npt.NDArray[np.float64], half_width: int) -> npt.NDArray[np.float64]:
    """Centred moving average along axis 1 with the ends repeated (zero phase)."""
    if half_width == 0:
        return a
    padded = np.concatenate(
        [np.repeat(a[:, :1], half_width, axis=1), a, np.repeat(a[:, -1:], half_width, axis=1)],
        axis=1)
    cumulative = np.cumsum(padded, axis=1)
    cumulative = np.concatenate([np.zeros_like(cumulative[:, :1]), cumulative], axis=1)
    width = 2 * half_width + 1
    return (cumulative[:, width:] - cumulative[:, :-width]) / width


class PidIlcController:
    """PID + iterative learning controllers for ``n`` tasks stepped together.

    Use per trial: `start_trial`, then `step` once per vision sample, then `finish_trial` to get
    the memory for the next trial of the same task.

    Parameters
    ----------
    n : int
        Number of tasks (arms); leading axis of every input and output.
    params : PidIlcParams
        Gains and limits.
    """

    def __init__(self, n: int = 1, params: PidIlcParams = PidIlcParams()) -> None:  # noqa: B008
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f'expected n an integer >= 1, got {n!r}')
        if not isinstance(params, PidIlcParams):
            raise ValueError(f'expected params a PidIlcParams, got {type(params).__name__}')
        self.n = int(n)
        self.params = params
        self._kp = np.asarray(params.kp, dtype=float)
        self._ki = np.asarray(params.ki, dtype=float)
        self._kd = np.asarray(params.kd, dtype=float)
        self._lead = np.asarray(params.learning_lead_steps, dtype=np.int64)
        self._preload = float(params.bellows_preload)
        self._antagonistic = self._preload > 0.0
        # errors are kept for the steps whose lead reaches into the memory window
        self._n_errors = params.memory_steps + int(self._lead.max())
        self._tail_start = params.memory_steps - 1 + self._lead  # (3,) first tail step per axis
        self._rows = np.arange(self.n)[:, None]
        self._table = np.array(
            [[CHAMBERS.index(b) for b in pair] for pair in params.quadrant_bellows])
        self._table_push = np.array([[BELLOWS_PUSH[pair[0]][0], BELLOWS_PUSH[pair[1]][1]]
                                     for pair in params.quadrant_bellows])
        self._active = False
        self._k = 0
        self.start = np.zeros((self.n, 3))
        self.target = np.zeros((self.n, 3))
        self._chamber = np.zeros((self.n, 3), dtype=np.int64)

    @property
    def chamber_of_axis(self) -> npt.NDArray[np.int64]:
        """Index into `CHAMBERS` of the chamber driving x, y, z per task, shape (n, 3) (with a
        ``bellows_preload``: the bellows pushing towards ``+x`` and ``+y``, B4 and B3)."""
        return self._chamber.copy()

    def start_trial(
        self,
        start: npt.ArrayLike,
        target: npt.ArrayLike,
        memory: npt.ArrayLike | None = None,
        initial_output: npt.ArrayLike | None = None,
    ) -> None:
        """Begin a trial from ``start`` to ``target``.

        Parameters
        ----------
        start, target : array-like, shape (3,) or (n, 3)
            Initial and desired end points in ``sra_mount`` [m]; both must lie in
            ``params.workspace`` (step 1 of section 4.2).
        memory : array-like, shape (memory_steps, 5) or (n, memory_steps, 5), optional
            ILC feedforward: valve outputs per step for this task (what `finish_trial` returned
            after the previous trial, or a knowledge-database entry) in `CHAMBERS` order [Pa].
            Only the chambers that drive this target's axes are used, each capped at its axis'
            ``p_set`` (eq. (4)). Beyond ``memory_steps`` the last entry is held.
        initial_output : array-like, shape (5,) or (n, 5), optional
            ``P_out,0`` of eq. (3) [Pa]; 0 kPa (default) as in the paper. It is the feedforward
            when there is no memory or learning is off.

        Raises
        ------
        ValueError
            On bad shapes, non-finite values, negative pressures or points outside the work
            space (the message names the violated bound).
        """
        p = self.params
        n, m = self.n, p.memory_steps
        start = _points(start, n, 'start', p.workspace)
        target = _points(target, n, 'target', p.workspace)
        if initial_output is None:
            init = np.zeros((n, _N_CHAMBERS))
        else:
            init = np.asarray(initial_output, dtype=float)
            if init.shape not in ((_N_CHAMBERS,), (n, _N_CHAMBERS)):
                raise ValueError(
                    f'expected initial_output of shape (5,) or ({n}, 5), got {init.shape}')
            if not np.all(np.isfinite(init)) or np.any(init < 0.0):
                raise ValueError('expected finite non-negative initial_output [Pa]')
            init = np.broadcast_to(init, (n, _N_CHAMBERS))
        if memory is not None:
            mem = np.asarray(memory, dtype=float)
            if mem.shape not in ((m, _N_CHAMBERS), (n, m, _N_CHAMBERS)):
                raise ValueError(
                    f'expected memory of shape ({m}, 5) or ({n}, {m}, 5), got {mem.shape}')
            if not np.all(np.isfinite(mem)) or np.any(mem < 0.0):
                raise ValueError('expected finite non-negative memory [Pa]')
            mem = np.broadcast_to(mem, (n, m, _N_CHAMBERS))
        if memory is None or not p.learning:
            mem = np.broadcast_to(init[:, None, :], (n, m, _N_CHAMBERS))

        self._chamber = np.empty((n, 3), dtype=np.int64)
        self._chamber[:, 2] = _PEA
        self._sign = np.ones((n, 3))
        p_max = np.asarray(p.p_max, dtype=float)
        p_set = np.asarray(p.p_set, dtype=float)
        if self._antagonistic:
            # signed outputs per axis: [-(p_max of the - bellows - P_0), p_max of + - P_0]
            self._chamber[:, :2] = _PAIRS[:, 0]
            self._p_max_axis = np.broadcast_to(
                np.append(p_max[_PAIRS[:, 0]] - self._preload, p_max[_PEA]), (n, 3)).copy()
            self._p_min_axis = np.broadcast_to(
                np.append(self._preload - p_max[_PAIRS[:, 1]], 0.0), (n, 3)).copy()
            ff = axis_outputs(mem)
            output = axis_outputs(init)
        else:
            quadrant = quadrant_of(target[:, 0], target[:, 1]) - 1
            self._chamber[:, :2] = self._table[quadrant]
            self._sign[:, :2] = self._table_push[quadrant]
            self._p_max_axis = p_max[self._chamber]
            self._p_min_axis = np.zeros((n, 3))
            ff = np.take_along_axis(mem, self._chamber[:, None, :], axis=2)
            output = np.take_along_axis(init, self._chamber, axis=1)
        self._p_set_axis = np.minimum(p_set, self._p_max_axis)
        self._p_set_min_axis = np.maximum(-p_set, self._p_min_axis)
        # feedforward per axis (n, m, 3), capped at P_set (eq. 4)
        self._ff = np.clip(ff, self._p_set_min_axis[:, None, :], self._p_set_axis[:, None, :])
        self.start = start
        self.target = target
        self._accumulated = np.zeros((n, 3))
        self._accumulated_at_memory_end = np.zeros((n, 3))
        self._integral = np.zeros((n, 3))
        self._previous_error = np.zeros((n, 3))
        self._have_previous = np.zeros((n, 1), dtype=bool)
        self._since_valid = np.zeros((n, 1))
        self._output = np.clip(output, self._p_min_axis, self._p_max_axis)
        self._command = self._chamber_command(self._output)
        self._errors = np.full((n, self._n_errors, 3), np.nan)  # NaN = no fresh measurement
        self._tail_sum = np.zeros((n, 3))
        self._tail_count = np.zeros((n, 3))
        self._k = 0
        self._active = True

    def _chamber_command(self, output: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Valve set pressures (n, 5) of the axis outputs (n, 3)."""
        if self._antagonistic:
            return antagonistic_pressures(output, self._preload)
        command = np.zeros((output.shape[0], _N_CHAMBERS))
        command[self._rows, self._chamber] = output
        return command

    def step(
        self, end_point: npt.ArrayLike, dt: float, valid: npt.ArrayLike | None = None
    ) -> npt.NDArray[np.float64]:
        """One control step: PID compensation (eq. (1)) accumulated on the feedforward (eq. (3)).

        Parameters
        ----------
        end_point : array-like, shape (n, 3)
            Measured end points in ``sra_mount`` [m]; must be finite where ``valid``.
        dt : float
            Time since the previous step [s], > 0 (``1 / rate_hz`` nominally).
        valid : array-like of bool, shape (n,), optional
            False where there is no fresh measurement (vision dropout): that task holds its last
            pressures, its PID state is frozen and this step teaches the memory nothing.
            Default: all valid.

        Returns
        -------
        command : ndarray, shape (n, 5)
            Valve set pressures in `CHAMBERS` order [Pa], within ``[0, p_max]``; chambers not
            driving an axis get 0 (every bellows at least ``bellows_preload`` with one).

        Raises
        ------
        ValueError
            If no trial is active, on a bad shape or ``dt``, or on a NaN/inf end point where
            ``valid``.
        """
        if not self._active:
            raise ValueError('expected start_trial() before step()')
        y = np.asarray(end_point, dtype=float)
        if y.shape != (self.n, 3):
            raise ValueError(f'expected end_point of shape ({self.n}, 3), got {y.shape}')
        if not (dt > 0.0 and np.isfinite(dt)):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        if valid is None:
            if not np.isfinite(y).all():
                raise ValueError('expected finite end_point [m], got NaN or inf')
            ok = None
        else:
            ok = np.asarray(valid, dtype=bool)
            if ok.shape != (self.n,):
                raise ValueError(f'expected valid of shape ({self.n},), got {ok.shape}')
            if not np.isfinite(y[ok]).all():
                raise ValueError('expected finite end_point [m] where valid, got NaN or inf')
            ok = ok[:, None]
            y = np.where(ok, y, self.target)  # placeholders, discarded below

        k = self._k
        ff = self._ff[:, min(k, self.params.memory_steps - 1)]
        error = self._sign * (self.target - y)
        elapsed = self._since_valid + dt
        integral = self._integral + error * dt
        derivative = np.where(self._have_previous, (error - self._previous_error) / elapsed, 0.0)
        raw = ff + self._accumulated + (self._kp * error + self._ki * integral
                                        + self._kd * derivative)
        output, integral = clip_without_windup(raw, self._p_min_axis, self._p_max_axis, error,
                                               integral, self._integral)
        accumulated = output - ff  # back-calculation: clipping never winds up eq. (3)
        if ok is None:
            self._integral = integral
            self._accumulated = accumulated
            self._previous_error = error
            self._have_previous[:] = True
            self._since_valid[:] = 0.0
            self._output = output
            recorded = error
        else:
            self._integral = np.where(ok, integral, self._integral)
            self._accumulated = np.where(ok, accumulated, self._accumulated)
            self._previous_error = np.where(ok, error, self._previous_error)
            self._have_previous |= ok
            self._since_valid = np.where(ok, 0.0, elapsed)
            self._output = np.where(ok, output, self._output)
            recorded = np.where(ok, error, np.nan)
        if k < self._n_errors:
            self._errors[:, k] = recorded
        tail = k >= self._tail_start
        if tail.any():
            fresh = np.isfinite(recorded) & tail
            self._tail_sum += np.where(fresh, recorded, 0.0)
            self._tail_count += fresh
        if k + 1 == self.params.memory_steps:
            self._accumulated_at_memory_end = self._accumulated.copy()
        self._command = self._chamber_command(self._output)
        self._k = k + 1
        return self._command.copy()

    def finish_trial(self) -> npt.NDArray[np.float64]:
        """End the trial and return the learned memory for the next trial of the same tasks.

        Applies the phase-lead learning update (module docstring) to this trial's feedforward.
        Steps whose lead error was lost to a vision dropout learn nothing from it; steps whose
        lead reaches past the end of a short trial learn from the last measured error.

        Returns
        -------
        memory : ndarray, shape (n, memory_steps, 5)
            Feedforward valve outputs per step in `CHAMBERS` order [Pa], each axis' chamber
            within ``[0, p_set]``, the other chambers 0 (with a ``bellows_preload``: each pair's
            signed output within ``[-p_set, p_set]``, by `antagonistic_pressures`).
        """
        if not self._active:
            raise ValueError('expected start_trial() before finish_trial()')
        p = self.params
        m = p.memory_steps
        errors = self._errors
        k = self._k
        if 0 < k < self._n_errors:
            # the trial ended before the lead reached these steps: the last measured error is
            # the best estimate of what followed (dropouts inside the trial stay unmeasured)
            errors = errors.copy()
            measured = np.isfinite(errors[:, :k])
            last = k - 1 - np.argmax(measured[:, ::-1], axis=1)  # (n, 3)
            final = np.take_along_axis(errors, last[:, None, :], axis=1)
            errors[:, k:] = np.where(measured.any(axis=1)[:, None, :], final, np.nan)
        lead_error = np.empty((self.n, m, 3))
        for axis in range(3):
            lead_error[:, :, axis] = errors[:, self._lead[axis]:self._lead[axis] + m, axis]
        with np.errstate(invalid='ignore', divide='ignore'):
            lead_error[:, -1] = np.where(self._tail_count > 0.0,
                                         self._tail_sum / self._tail_count, lead_error[:, -1])
        lead_error = np.nan_to_num(lead_error, nan=0.0)
        taught = np.sign(lead_error) * np.maximum(np.abs(lead_error) - p.learning_dead_band, 0.0)
        update = np.asarray(p.learning_gain) * _moving_average(taught, p.learning_filter_steps)
        if k > m:
            # what the PID added while the memory's last entry was held: the steady offset the
            # hold lacked (what it added while the arm moved is the error-driven term's)
            update += np.asarray(p.learning_feedback_gain) * (
                self._accumulated - self._accumulated_at_memory_end)[:, None, :]
        learned = np.clip(self._ff + update, self._p_set_min_axis[:, None, :],
                          self._p_set_axis[:, None, :])
        if self._antagonistic:
            memory = antagonistic_pressures(learned, self._preload)
        else:
            memory = np.zeros((self.n, m, _N_CHAMBERS))
            memory[self._rows, :, self._chamber] = learned.transpose(0, 2, 1)
        self._active = False
        return memory


@dataclass(frozen=True)
class TrialResults:
    """Outcome of `run_trials`.

    Attributes
    ----------
    times : ndarray, shape (steps + 1,)
        Sample times from the start of each trial [s]; sample ``k`` is taken before command ``k``.
    trajectories : ndarray, shape (n_trials, steps + 1, n, 3) or None
        Measured end points per trial, sample and task in ``sra_mount`` [m], NaN where the
        measurement dropped out (None if not kept).
    rmse : ndarray, shape (n_trials, n, 3)
        Root-mean-square of ``zeta_e - zeta_d`` over the measured samples of a trial, per axis
        [m] (Fig 8).
    reach_time : ndarray, shape (n_trials, n, 3)
        Per axis, the first sample time after which the measured coordinate stays within
        ``tolerance`` of the target until the end of the trial [s]; ``inf`` if it is outside at
        the last sample.
    memory : ndarray, shape (n, memory_steps, 5)
        ILC memory after the last trial [Pa] (what a knowledge-database point stores).
    tolerance : float
        Reach tolerance [m].
    """

    times: npt.NDArray[np.float64]
    trajectories: npt.NDArray[np.float64] | None
    rmse: npt.NDArray[np.float64]
    reach_time: npt.NDArray[np.float64]
    memory: npt.NDArray[np.float64]
    tolerance: float


def run_trials(
    plant,
    controller: PidIlcController,
    start: npt.ArrayLike,
    target: npt.ArrayLike,
    n_trials: int,
    duration_s: float,
    dt: float = 0.2,
    memory: npt.ArrayLike | None = None,
    *,
    tolerance: float = 0.005,
    keep_trajectories: bool = True,
) -> TrialResults:
    """Repeat the task ``start -> target`` ``n_trials`` times, learning between trials (Fig 7-8).

    Each trial resets the plant to hold ``start`` (``plant.reset(end_point=start)``), starts the
    controller from the plant's chamber pressures (``P_out,0``) with the previous trial's memory,
    and runs ``round(duration_s / dt)`` control steps. Reach time and RMSE are accumulated on the
    fly, so ``keep_trajectories=False`` keeps memory use independent of the trial length.

    Parameters
    ----------
    plant : SoftArmPlant-like
        Object with ``n``, ``reset(end_point=...)``, ``chamber_pressures``, ``measure()`` and
        ``step(command, dt)`` (e.g. ``inflarm_hw.sra_plant.SoftArmPlant``). A row of NaN from
        ``measure()`` is a vision dropout of that task: the controller holds and learns nothing
        from the step (``PidIlcController.step(..., valid)``), and the sample counts in neither
        RMSE nor reach time.
    controller : PidIlcController
        Controller with the same ``n`` as the plant.
    start, target : array-like, shape (3,) or (n, 3)
        In ``sra_mount`` [m].
    n_trials : int
        Number of repetitions, >= 1.
    duration_s : float
        Length of each trial [s], >= dt.
    dt : float
        Control period [s].
    memory : array-like, shape (memory_steps, 5) or (n, memory_steps, 5), optional
        Memory for the first trial (e.g. from the knowledge database) [Pa]; None = PID alone.
    tolerance : float
        Reach tolerance per axis [m], > 0.
    keep_trajectories : bool
        Keep the measured trajectories in the result.

    Returns
    -------
    TrialResults
    """
    if isinstance(n_trials, bool) or int(n_trials) != n_trials or n_trials < 1:
        raise ValueError(f'expected n_trials an integer >= 1, got {n_trials}')
    if not (np.isfinite(dt) and dt > 0.0):
        raise ValueError(f'expected dt > 0 s, got {dt}')
    if not (np.isfinite(duration_s) and duration_s >= dt):
        raise ValueError(f'expected duration_s >= dt = {dt} s, got {duration_s}')
    if not (np.isfinite(tolerance) and tolerance > 0.0):
        raise ValueError(f'expected tolerance > 0 m, got {tolerance}')
    if plant.n != controller.n:
        raise ValueError(f'expected plant.n == controller.n, got {plant.n} and {controller.n}')
    n = controller.n
    start = _points(start, n, 'start')
    target = _points(target, n, 'target')
    steps = int(round(duration_s / dt))
    times = np.arange(steps + 1) * dt
    trajectories = np.empty((n_trials, steps + 1, n, 3)) if keep_trajectories else None
    rmse = np.empty((n_trials, n, 3))
    reach = np.empty((n_trials, n, 3))
    for t in range(n_trials):
        plant.reset(end_point=start)
        controller.start_trial(start, target, memory, initial_output=plant.chamber_pressures)
        metrics = TrialMetrics(target, tolerance)
        for k in range(steps + 1):
            y = plant.measure()
            if trajectories is not None:
                trajectories[t, k] = y
            valid = np.isfinite(y).all(axis=-1)
            valid = None if valid.all() else valid  # a NaN row: that task's dropout
            metrics.add(y, times[k], valid)
            if k < steps:
                plant.step(controller.step(y, dt, valid), dt)
        memory = controller.finish_trial()
        rmse[t] = metrics.rmse
        reach[t] = metrics.reach_time
    return TrialResults(times, trajectories, rmse, reach, memory, float(tolerance))
