"""Following a planned path with the soft arm's end: a moving reference, feedforward and PI.

Section 4.2 of ``001_b59ad71c956a1751`` has the controller track the planned path's waypoints;
section 4.3 reports an error under 5 mm. Stepping from waypoint to waypoint, each a PID trial
of `inflarm_control.pid_ilc` (eq. (3) integrates, so its ``K_P`` acts as a slow integral gain),
leaves a steady lag behind the path's z ramp and limit cycles where an axis output passes
through zero (a bellows leaving the valves' dead zone jumps), so this module follows a path
differently, in three parts:

- a reference point moving along the path (arc length ``s``, from the point of the path nearest
  to the end when the path starts) at up to ``speed``, slowing down
  linearly between ``slow_error`` and ``stop_error`` of distance from the measured end to it and
  waiting beyond: the arm sets the pace, so lagging never turns into cutting corners (the error
  that counts is the distance to the path, not to a schedule);
- a feedforward: the holding pressures at the waypoints (e.g. the experiential knowledge
  database's, `inflarm_control.knowledge.holding_pressure`), interpolated along the path at the
  reference ``feedforward_lead`` seconds ahead, as signed axis outputs (`axis_outputs`), the
  lateral ones shrunk by ``feedforward_dead_zone`` towards zero (`shrink_lateral_outputs`);
- per axis a PI on the error to the reference, added to the feedforward::

      u = u_ff(s + lead) + I + K_P e,   I <- I + K_I e dt   (not while u is clipped that way)
      e = r(s) - zeta_e

  and the signed outputs ``u`` driving the bellows pairs antagonistically around
  ``bellows_preload`` (`antagonistic_pressures`), PEA1&2 with ``u_z``;
- the alert regions' repulsion (section 4.3.2: "the control algorithm adopted the repulsive
  effect to keep the SRA's end out of the alert region"): while the measured end is inside an
  obstacle's alert region (`set_alert_regions`), the PI's target is pulled from the reference
  towards the region's border, to the weighted mean of the two::

      target = (r(s) + k_rep q) / (1 + k_rep),   q = zeta_e + d(zeta_e)

  with ``d`` the shortest way out (`inflarm_model.alert_regions.repulsive_offset`: along the
  nearest face's outward normal, as long as the end is deep; 0 outside every region) and ``q``
  the point of the border it leads to. So the push out of the region grows with the penetration
  (``e = (r - zeta_e + k_rep d) / (1 + k_rep)``), a path running inside a region is followed
  ``1 + k_rep`` times less deep, and the loop's gain towards the border stays the PI's (adding
  ``k_rep d`` to the error instead would raise it ``1 + k_rep`` times, enough to set the loop
  oscillating: ``inflarm_control/README.md``).
  The reference's pace follows the distance to the target, so that it moves on while the end
  is held out of a region (measured from the path, it would wait for ever where the path runs
  inside one).

Everything is pure numpy, one arm, no rclpy.
"""

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from inflarm_control.pid_ilc import antagonistic_pressures, axis_outputs, clip_without_windup
from inflarm_model.alert_regions import check_regions, repulsive_offset
from inflarm_model.soft_arm import (
    CHAMBER_MAX_PRESSURE,
    CHAMBERS,
    WORKSPACE_POSITIVE,
    Workspace,
    check_in_workspace,
)

_N_CHAMBERS = len(CHAMBERS)


@dataclass(frozen=True)
class PathFollowingParams:
    """Gains, pace and limits of `PathFollower`.

    Attributes
    ----------
    kp : tuple of 3 float
        Proportional gain per axis x, y, z [Pa/m].
    ki : tuple of 3 float
        Integral gain per axis [Pa/(m s)].
    bellows_preload : float
        Common pressure of each bellows pair at a zero lateral output [Pa], >= 0; above the
        valves' 4 kPa dead zone no bellows exhausts while the end crosses an axis.
    p_max : tuple of 5 float
        Valve output limit per chamber in `CHAMBERS` order [Pa].
    speed : float
        Top speed of the reference along the path [m/s], > 0.
    slow_error : float
        Distance from the measured end to the reference up to which it moves at ``speed`` [m].
    stop_error : float
        Distance at and beyond which the reference waits [m], > ``slow_error``; in between its
        speed falls linearly.
    feedforward_lead : float
        The feedforward is taken this long ahead of the reference at ``speed`` [s], >= 0:
        about the plant's lag (the valves' 0.1 s, the PEA's 1 s and the bellows' 0.6 s time
        constants, the walls' creep), so the integral need not carry the ramp and does not
        overshoot where the path turns or ends. On the paper's obstacle scenario (seeds 1, 2,
        3, 7, one step of latency): 1.5-2.0 mm at most from the path with 2.5 s, 1.9-2.1 mm
        with 2 s, 2.4-2.7 mm with 1.5 s.
    feedforward_dead_zone : float
        The feedforward's x and y outputs shrink by this much towards zero [Pa], >= 0: holding
        pressures learned under the quadrant rule (the knowledge database's) carry the valves'
        4 kPa dead zone, which the preloaded bellows never enter (`shrink_lateral_outputs`).
    repulsion_gain : float
        ``k_rep``: while the end is in an alert region, the PI's target is
        ``(r + k_rep q) / (1 + k_rep)``, ``q`` the nearest point of the region's border, >= 0
        (0: no repulsion).
    workspace : Workspace
        Bounds every waypoint must respect.
    """

    kp: tuple[float, float, float] = (200e3, 200e3, 50e3)
    ki: tuple[float, float, float] = (300e3, 300e3, 100e3)
    bellows_preload: float = 6e3
    p_max: tuple[float, float, float, float, float] = (CHAMBER_MAX_PRESSURE,) * 5
    speed: float = 0.003
    slow_error: float = 0.0015
    stop_error: float = 0.004
    feedforward_lead: float = 2.5
    feedforward_dead_zone: float = 4e3
    repulsion_gain: float = 1.0
    workspace: Workspace = WORKSPACE_POSITIVE

    def __post_init__(self) -> None:
        for name, size in (('kp', 3), ('ki', 3), ('p_max', 5)):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (size,):
                raise ValueError(f'expected {name} of shape ({size},), got {value.shape}')
            if not np.all(np.isfinite(value)) or np.any(value < 0.0):
                raise ValueError(f'expected finite non-negative {name}, got {value.tolist()}')
        if not np.all(np.asarray(self.p_max) > 0.0):
            raise ValueError(f'expected p_max > 0 Pa per chamber, got {self.p_max}')
        if not (math.isfinite(self.bellows_preload)
                and 0.0 <= self.bellows_preload < min(self.p_max[1:])):
            raise ValueError(f'expected 0 <= bellows_preload < the bellows p_max '
                             f'{min(self.p_max[1:])} Pa, got {self.bellows_preload}')
        if not (math.isfinite(self.speed) and self.speed > 0.0):
            raise ValueError(f'expected speed > 0 m/s, got {self.speed}')
        if not (math.isfinite(self.slow_error) and self.slow_error >= 0.0):
            raise ValueError(f'expected slow_error >= 0 m, got {self.slow_error}')
        if not (math.isfinite(self.stop_error) and self.stop_error > self.slow_error):
            raise ValueError(f'expected stop_error > slow_error = {self.slow_error} m, got '
                             f'{self.stop_error}')
        if not (math.isfinite(self.feedforward_lead) and self.feedforward_lead >= 0.0):
            raise ValueError(f'expected feedforward_lead >= 0 s, got {self.feedforward_lead}')
        if not (math.isfinite(self.feedforward_dead_zone) and self.feedforward_dead_zone >= 0.0):
            raise ValueError(
                f'expected feedforward_dead_zone >= 0 Pa, got {self.feedforward_dead_zone}')
        if not (math.isfinite(self.repulsion_gain) and self.repulsion_gain >= 0.0):
            raise ValueError(f'expected repulsion_gain >= 0, got {self.repulsion_gain}')


def shrink_lateral_outputs(outputs: npt.ArrayLike, dead_zone: float) -> npt.NDArray[np.float64]:
    """Signed axis outputs with x and y moved ``dead_zone`` towards zero (z unchanged).

    ``u -> sign(u) max(|u| - dead_zone, 0)``. Under the quadrant rule an axis acts only once
    its bellows is past the valves' dead zone, so a holding pressure learned that way is that
    much larger than what the preloaded pair needs. On the fitted plant this took the paper's
    obstacle scenario from 2.4-5.0 mm at most off the path to 2.4-2.8 mm; on the physical one
    (6 seeds, one/two steps of latency) it makes no difference that counts: 1.4-1.6 / 1.5-2.8 mm
    with 4 kPa, 1.5-1.7 / 1.6-1.8 mm unshrunk.

    Parameters
    ----------
    outputs : array-like, shape (..., 3)
        ``(u_x, u_y, u_z)`` [Pa] (`axis_outputs`).
    dead_zone : float
        [Pa], >= 0.
    """
    u = np.array(outputs, dtype=float)
    if u.ndim == 0 or u.shape[-1] != 3:
        raise ValueError(f'expected outputs of shape (..., 3), got {u.shape}')
    lateral = u[..., :2]
    u[..., :2] = np.sign(lateral) * np.maximum(np.abs(lateral) - dead_zone, 0.0)
    return u


def project_on_polyline(
    points: npt.ArrayLike, polyline: npt.ArrayLike
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Each point's distance to a polyline, and the arc length of its nearest point on it.

    Parameters
    ----------
    points : array-like, shape (N, 3)
    polyline : array-like, shape (M, 3), M >= 2

    Returns
    -------
    distances, arcs : ndarray, shape (N,)
        [m]; of equally near points of the polyline, the first along it.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    line = np.asarray(polyline, dtype=float)
    if line.ndim != 2 or line.shape[1] != 3 or len(line) < 2:
        raise ValueError(f'expected a polyline of shape (M, 3), M >= 2, got {line.shape}')
    a, ab = line[:-1], np.diff(line, axis=0)
    lengths = np.einsum('mi,mi->m', ab, ab)
    t = np.clip(np.einsum('nmi,mi->nm', p[:, None, :] - a[None], ab)
                / np.maximum(lengths, 1e-18), 0.0, 1.0)
    distances = np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=-1)
    segment = distances.argmin(axis=1)
    rows = np.arange(len(p))
    arc = np.concatenate([[0.0], np.cumsum(np.sqrt(lengths))])
    return distances[rows, segment], arc[segment] + t[rows, segment] * np.sqrt(lengths)[segment]


def _vector(value: npt.ArrayLike, size: int, name: str, unit: str) -> npt.NDArray[np.float64]:
    a = np.asarray(value, dtype=float)
    if a.shape != (size,):
        raise ValueError(f'expected {name} of shape ({size},), got {a.shape}')
    if not np.isfinite(a).all():
        raise ValueError(f'expected finite {name} [{unit}], got {a.tolist()}')
    return a


class PathFollower:
    """Drives one arm's end along a path (module docstring).

    Use: `start` with the path, the measured end and the pressures held now (the first outputs
    continue them: no jump), then `step` once per vision sample. After the reference reaches
    the path's end the follower keeps holding the last waypoint. `set_alert_regions` gives the
    obstacles' alert regions (at any time; none at first).

    Parameters
    ----------
    params : PathFollowingParams
    """

    def __init__(self, params: PathFollowingParams = PathFollowingParams()) -> None:  # noqa: B008
        if not isinstance(params, PathFollowingParams):
            raise ValueError(
                f'expected params a PathFollowingParams, got {type(params).__name__}')
        self.params = params
        self._kp = np.asarray(params.kp, dtype=float)
        self._ki = np.asarray(params.ki, dtype=float)
        limit = dict(zip(CHAMBERS, params.p_max, strict=True))
        preload = params.bellows_preload
        # signed outputs: x within [-(p_max B2 - P_0), p_max B4 - P_0], y likewise, z [0, PEA]
        self._high = np.array([limit['B4'] - preload, limit['B3'] - preload, limit['PEA']])
        self._low = np.array([preload - limit['B2'], preload - limit['B1'], 0.0])
        self._active = False
        self._regions = np.zeros((0, 2, 3))
        self._repulsion = np.zeros(3)

    # -- state ---------------------------------------------------------------------------------

    @property
    def active(self) -> bool:
        """Whether a path has been started."""
        return self._active

    @property
    def length(self) -> float:
        """Length of the current path [m]."""
        self._check_active()
        return float(self._arc[-1])

    @property
    def progress(self) -> float:
        """Arc length of the reference along the path [m], in ``[0, length]``."""
        self._check_active()
        return self._s

    @property
    def reference(self) -> npt.NDArray[np.float64]:
        """The reference point now, shape (3,) [m, sra_mount]."""
        self._check_active()
        return self._point(self._s)

    @property
    def at_end(self) -> bool:
        """Whether the reference has reached the path's last waypoint."""
        self._check_active()
        return self._s >= self._arc[-1]

    @property
    def goal(self) -> npt.NDArray[np.float64]:
        """The path's last waypoint, shape (3,) [m]."""
        self._check_active()
        return self._path[-1].copy()

    @property
    def alert_regions(self) -> npt.NDArray[np.float64]:
        """The alert regions repelling the end, shape (K, 2, 3) [m]."""
        return self._regions.copy()

    @property
    def repulsion(self) -> npt.NDArray[np.float64]:
        """The shortest way out of the alert regions at the last step's measured end, shape (3,)
        [m] (`repulsive_offset`; 0 outside them)."""
        return self._repulsion.copy()

    def _check_active(self) -> None:
        if not self._active:
            raise ValueError('expected start() first')

    def _point(self, s: float) -> npt.NDArray[np.float64]:
        return np.array([np.interp(s, self._arc, self._path[:, i]) for i in range(3)])

    def _feedforward(self, s: float) -> npt.NDArray[np.float64]:
        if self._ff is None:
            return np.zeros(3)
        return np.array([np.interp(s, self._arc, self._ff[:, i]) for i in range(3)])

    # -- use -----------------------------------------------------------------------------------

    def start(
        self,
        path: npt.ArrayLike,
        end_point: npt.ArrayLike,
        held_pressures: npt.ArrayLike,
        feedforward: npt.ArrayLike | None = None,
    ) -> None:
        """Begin following ``path`` from where the end is: the reference starts at the path's
        point nearest to ``end_point``.

        Parameters
        ----------
        path : array-like, shape (N, 3)
            Waypoints in ``sra_mount`` [m], N >= 1, each in ``params.workspace``; repeated
            consecutive points are dropped. One waypoint: hold it.
        end_point : array-like, shape (3,)
            Measured end point now [m].
        held_pressures : array-like, shape (5,)
            Chamber set pressures commanded now in `CHAMBERS` order [Pa], >= 0: the first
            outputs continue them (the integral starts at what the feedforward lacks).
        feedforward : array-like, shape (N, 5), optional
            Holding pressures at each waypoint in `CHAMBERS` order [Pa], >= 0 (from any
            bellows scheme: only their `axis_outputs` are used). None: PI alone.

        Raises
        ------
        ValueError
            On bad shapes, non-finite or negative values or waypoints outside the work space
            (naming the argument).
        """
        p = np.asarray(path, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 1:
            raise ValueError(f'expected path of shape (N, 3), N >= 1, got {p.shape}')
        check_in_workspace(p, self.params.workspace, 'waypoint')
        y = _vector(end_point, 3, 'end_point', 'm')
        held = _vector(held_pressures, _N_CHAMBERS, 'held_pressures', 'Pa')
        if np.any(held < 0.0):
            raise ValueError(f'expected non-negative held_pressures [Pa], got {held.tolist()}')
        ff = None
        if feedforward is not None:
            ff = np.asarray(feedforward, dtype=float)
            if ff.shape != (len(p), _N_CHAMBERS):
                raise ValueError(
                    f'expected feedforward of shape ({len(p)}, 5), got {ff.shape}')
            if not np.isfinite(ff).all() or np.any(ff < 0.0):
                raise ValueError('expected finite non-negative feedforward [Pa]')
        keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 0.0])
        self._path = p[keep]
        self._ff = None if ff is None else shrink_lateral_outputs(
            axis_outputs(ff[keep]), self.params.feedforward_dead_zone)
        self._arc = np.concatenate(
            [[0.0], np.cumsum(np.linalg.norm(np.diff(self._path, axis=0), axis=1))])
        self._s = self._nearest_arc(y)
        self._active = True
        error = self._point(self._s) - y
        self._integral = axis_outputs(held) - self._feedforward(self._lead_arc()) \
            - self._kp * error
        self._command = held.copy()

    def set_alert_regions(self, regions: npt.ArrayLike) -> None:
        """Repel the end from these alert regions from the next step on.

        Parameters
        ----------
        regions : array-like, shape (K, 2, 3)
            Obstacles grown by their alert margin, min and max corners in ``sra_mount`` [m]
            (`inflarm_model.alert_regions.grow_boxes`); K = 0: none.
        """
        self._regions = check_regions(regions).copy()

    def _nearest_arc(self, point: npt.NDArray[np.float64]) -> float:
        """Arc length of the path's point nearest to ``point``. A path planned from where the
        end was may arrive after it moved on (a trial still running): starting behind it, the
        reference would wait for the arm to come back, for ever if that start is out of its
        reach."""
        if len(self._path) == 1:
            return 0.0
        return float(project_on_polyline(point[None], self._path)[1][0])

    def _lead_arc(self) -> float:
        return self._s + self.params.feedforward_lead * self.params.speed

    def step(self, end_point: npt.ArrayLike, dt: float, valid: bool = True
             ) -> npt.NDArray[np.float64]:
        """One control step.

        Parameters
        ----------
        end_point : array-like, shape (3,)
            Measured end point [m]; must be finite if ``valid``.
        dt : float
            Time since the previous step [s], > 0.
        valid : bool
            False when there is no fresh measurement: the pressures, the integral and the
            reference are held.

        Returns
        -------
        command : ndarray, shape (5,)
            Valve set pressures in `CHAMBERS` order [Pa], within ``[0, p_max]``.
        """
        self._check_active()
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        if not valid:
            return self._command.copy()
        y = _vector(end_point, 3, 'end_point', 'm')
        params = self.params
        lag = self._point(self._s) - y
        self._repulsion = repulsive_offset(y, self._regions)
        error = lag
        if self._repulsion.any():  # the target (r + k q) / (1 + k), q = y + offset
            k = params.repulsion_gain
            error = (lag + k * self._repulsion) / (1.0 + k)
        integral = self._integral + self._ki * error * dt
        raw = self._feedforward(self._lead_arc()) + integral + self._kp * error
        output, self._integral = clip_without_windup(raw, self._low, self._high, error, integral,
                                                     self._integral)
        self._command = np.minimum(antagonistic_pressures(output, params.bellows_preload),
                                   params.p_max)
        distance = float(np.linalg.norm(error))
        pace = min(max((params.stop_error - distance)
                       / (params.stop_error - params.slow_error), 0.0), 1.0)
        self._s = min(self._s + pace * params.speed * dt, float(self._arc[-1]))
        return self._command.copy()
