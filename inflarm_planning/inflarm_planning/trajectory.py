"""From a grid path to a trajectory the pressure controller can follow (sections 4.2-4.3).

``plan_trajectory`` = `inflarm_planning.astar.plan` + `make_trajectory`:

1. `simplify`: drop grid points where the path goes straight on.
2. `shortcut`: from each kept point jump to the farthest later point that the end can reach in a
   straight line without the arm touching an alert region (`motions_collide`: the end's path
   exactly, the PEA axes at poses ``check_step`` apart).
3. `smooth`: Chaikin corner cutting, a corner being cut only where the new segment passes the
   same test (a quarter of each adjacent segment, halved up to three times if that collides);
   the rest of the path lies on segments already tested.
4. `resample`: points no farther apart than ``max_step``, every vertex kept, so the controller's
   waypoint-by-waypoint PID never cuts a corner by more than its own tolerance.
5. `time_parameterize`: a trapezoidal speed profile along the length (``max_speed``,
   ``max_accel``) gives each point the time it is due.

Only the grid path's own steps are kept without a test when no shortcut from a point passes:
their guarantees are those of the grid (see ``README.md``); everything the smoothing adds is
tested.
"""

from collections.abc import Iterable
from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from inflarm_model.validation import check_positive
from inflarm_planning.astar import PlanResult, plan
from inflarm_planning.collision import CHECK_STEP, box_array, check_margin, motions_collide

SHORTCUT_BATCH = 32
"""Candidate shortcuts tested per vectorized call, farthest first."""

CUT_FRACTION = 0.25
"""Chaikin's cut: a quarter of each segment next to a corner."""

CUT_RETRIES = 3
"""A colliding cut is halved and retried this many times before the corner is kept."""


@dataclass(frozen=True)
class Trajectory:
    """Waypoints of the end with the times they are due.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        Waypoints in ``sra_mount`` [m], from start to goal.
    times : ndarray, shape (N,)
        Time each waypoint is due, from 0, strictly increasing [s].
    """

    points: npt.NDArray[np.float64]
    times: npt.NDArray[np.float64]

    @property
    def duration(self) -> float:
        """Time from the first to the last waypoint [s]."""
        return float(self.times[-1])

    @property
    def length(self) -> float:
        """Length of the polyline through the waypoints [m]."""
        return path_length(self.points)


@dataclass(frozen=True)
class TrajectoryPlan:
    """A grid plan and the trajectory made from it.

    Attributes
    ----------
    grid : PlanResult
        The A* result (grid path, search figures, free space).
    trajectory : Trajectory
        The shortcut, smoothed, resampled and timed path.
    """

    grid: PlanResult
    trajectory: Trajectory


def _check_path(path: npt.ArrayLike) -> npt.NDArray[np.float64]:
    p = np.asarray(path, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise ValueError(f'expected path of shape (N >= 2, 3), got {p.shape}')
    if not np.all(np.isfinite(p)):
        raise ValueError('expected a finite path [m]')
    return p


def path_length(path: npt.ArrayLike) -> float:
    """Length of a polyline, shape (N, 3) [m]."""
    p = np.asarray(path, dtype=float)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def simplify(path: npt.ArrayLike, tolerance: float = 1e-9) -> npt.NDArray[np.float64]:
    """Drop the interior points where the path goes straight on (and repeated points).

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Polyline [m].
    tolerance : float
        A point closer than this to the previous one is a repeat [m]; a point where the unit
        directions before and after it differ by less than this (their cross product) and do
        not reverse is on a straight run.

    Returns
    -------
    path : ndarray, shape (M, 3), M <= N
        Same first and last points.
    """
    p = _check_path(path)
    step = np.diff(p, axis=0)
    moving = np.linalg.norm(step, axis=1) > tolerance
    p = np.vstack([p[0], p[1:][moving]])
    if len(p) < 2:
        return np.vstack([p[0], p[0]])
    d = np.diff(p, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    turn = np.linalg.norm(np.cross(d[:-1], d[1:]), axis=1) > tolerance
    reverse = np.einsum('ij,ij->i', d[:-1], d[1:]) < 0.0
    keep = np.concatenate([[True], turn | reverse, [True]])
    return p[keep]


def shortcut(
    path: npt.ArrayLike, boxes: npt.ArrayLike, check_step: float = CHECK_STEP
) -> npt.NDArray[np.float64]:
    """Greedy shortcutting: from each point, go straight to the farthest reachable later point.

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Collision-free polyline [m] (e.g. a simplified grid path).
    boxes : array-like, shape (K, 2, 3)
        Alert regions [m] (`inflarm_planning.collision.box_array`).
    check_step : float
        Pose spacing of the motion test [m].

    Returns
    -------
    path : ndarray, shape (M, 3)
        A subsequence of ``path`` with the same ends.
    """
    p = _check_path(path)
    check_step = check_positive('check_step', check_step, 'm', 'length')
    kept = [0]
    i = 0
    while i < len(p) - 1:
        nxt = i + 1  # the path's own step, if no shortcut passes
        for first in range(len(p) - 1, i + 1, -SHORTCUT_BATCH):
            candidates = np.arange(first, max(first - SHORTCUT_BATCH, i + 1), -1)
            free = ~motions_collide(p[i], p[candidates], boxes, check_step)
            if free.any():
                nxt = int(candidates[np.argmax(free)])
                break
        kept.append(nxt)
        i = nxt
    return p[kept]


def smooth(
    path: npt.ArrayLike, boxes: npt.ArrayLike, iterations: int = 3,
    check_step: float = CHECK_STEP,
) -> npt.NDArray[np.float64]:
    """Round the corners by Chaikin corner cutting where the cut stays free.

    Each iteration replaces every interior corner ``P`` (neighbours ``A``, ``B``) by the two
    points ``P + c (A - P)/|A - P|`` and ``P + c (B - P)/|B - P|`` with ``c`` a quarter of the
    shorter adjacent segment, if the arm can move straight between them (`motions_collide`);
    otherwise ``c`` is halved, up to `CUT_RETRIES` times, and then the corner is kept. The new
    points lie on the old segments, so only the cuts need testing.

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Collision-free polyline [m].
    boxes : array-like, shape (K, 2, 3)
        Alert regions [m].
    iterations : int
        Rounds of cutting, >= 0 (each at most doubles the number of points).
    check_step : float
        Pose spacing of the motion test [m].

    Returns
    -------
    path : ndarray, shape (M, 3)
        Same first and last points.
    """
    p = _check_path(path)
    check_step = check_positive('check_step', check_step, 'm', 'length')
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) \
            or iterations < 0:
        raise ValueError(f'expected iterations to be an int >= 0, got {iterations!r}')
    for _ in range(int(iterations)):
        if len(p) < 3:
            break
        corner = p[1:-1]
        before, after = p[:-2] - corner, p[2:] - corner
        len_before = np.linalg.norm(before, axis=1)
        len_after = np.linalg.norm(after, axis=1)
        cut = CUT_FRACTION * np.minimum(len_before, len_after)
        sharp = cut > 0.0  # a repeated point is no corner to cut
        u_before = before / np.where(sharp, len_before, 1.0)[:, None]
        u_after = after / np.where(sharp, len_after, 1.0)[:, None]
        done = np.zeros(len(corner), dtype=bool)
        a = corner.copy()
        b = corner.copy()
        for _ in range(CUT_RETRIES + 1):
            todo = np.flatnonzero(~done & sharp)
            if not len(todo):
                break
            qa = corner[todo] + cut[todo, None] * u_before[todo]
            qb = corner[todo] + cut[todo, None] * u_after[todo]
            ok = ~motions_collide(qa, qb, boxes, check_step)
            a[todo[ok]], b[todo[ok]] = qa[ok], qb[ok]
            done[todo[ok]] = True
            cut[todo[~ok]] /= 2.0
        rows = [p[:1]]
        for k in range(len(corner)):
            rows.append(np.vstack([a[k], b[k]]) if done[k] else corner[k:k + 1])
        rows.append(p[-1:])
        p = np.vstack(rows)
    return p


def resample(path: npt.ArrayLike, max_step: float) -> npt.NDArray[np.float64]:
    """Insert evenly spaced points so that consecutive points are at most ``max_step`` apart.

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Polyline [m].
    max_step : float
        Largest spacing [m], > 0.

    Returns
    -------
    path : ndarray, shape (M, 3), M >= N
        Every original point is kept; the new ones lie on the segments.
    """
    p = _check_path(path)
    max_step = check_positive('max_step', max_step, 'm', 'length')
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    pieces = np.maximum(np.ceil(lengths / max_step - 1e-9).astype(np.int64), 1)
    rows = []
    for k, n in enumerate(pieces):
        t = np.arange(n)[:, None] / n
        rows.append(p[k] + t * (p[k + 1] - p[k]))
    rows.append(p[-1:])
    return np.vstack(rows)


def time_parameterize(
    path: npt.ArrayLike, max_speed: float, max_accel: float
) -> npt.NDArray[np.float64]:
    """Times at which the points are due along a trapezoidal speed profile.

    The end starts and stops at rest, accelerates at ``max_accel`` up to ``max_speed``, cruises
    and decelerates, measured along the path's length (corners are not slowed down for: the
    controller tracks the waypoints, not a velocity).

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Polyline without repeated points [m].
    max_speed : float
        Cruise speed [m/s], > 0.
    max_accel : float
        Acceleration and deceleration [m/s^2], > 0.

    Returns
    -------
    times : ndarray, shape (N,)
        From 0, strictly increasing [s].
    """
    p = _check_path(path)
    v = check_positive('max_speed', max_speed, 'm/s', 'speed')
    a = check_positive('max_accel', max_accel, 'm/s^2', 'acceleration')
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    if np.any(lengths <= 0.0):
        raise ValueError('expected a path without repeated points')
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    total = s[-1]
    ramp = v * v / (2.0 * a)  # distance to reach max_speed
    if total >= 2.0 * ramp:
        duration = total / v + v / a
        t = np.where(s < ramp, np.sqrt(2.0 * s / a), v / a + (s - ramp) / v)
        t = np.where(s > total - ramp, duration - np.sqrt(2.0 * np.maximum(total - s, 0.0) / a),
                     t)
    else:  # never reaches max_speed: accelerate over half the path, decelerate over the rest
        duration = 2.0 * math.sqrt(total / a)
        t = np.where(s <= total / 2.0, np.sqrt(2.0 * s / a),
                     duration - np.sqrt(2.0 * np.maximum(total - s, 0.0) / a))
    t[0], t[-1] = 0.0, duration
    return t


def make_trajectory(
    path: npt.ArrayLike,
    obstacles: Iterable,
    alert_margin: float,
    *,
    max_step: float = 0.005,
    max_speed: float = 0.005,
    max_accel: float = 0.005,
    smoothing: int = 3,
    check_step: float = CHECK_STEP,
) -> Trajectory:
    """Shortcut, smooth, resample and time a collision-free path (module docstring).

    Parameters
    ----------
    path : array-like, shape (N, 3)
        Collision-free path of the end [m], e.g. from `inflarm_planning.astar.plan_path`.
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
    alert_margin : float
        Growth of each obstacle per axis [m], >= 0.
    max_step : float
        Largest waypoint spacing [m].
    max_speed : float
        Cruise speed [m/s].
    max_accel : float
        Acceleration [m/s^2].
    smoothing : int
        Chaikin iterations, >= 0.
    check_step : float
        Pose spacing of the motion tests [m].

    Returns
    -------
    Trajectory
    """
    boxes = box_array(obstacles, check_margin(alert_margin))
    p = simplify(path)
    p = shortcut(p, boxes, check_step)
    p = smooth(p, boxes, smoothing, check_step)
    p = resample(p, max_step)
    return Trajectory(p, time_parameterize(p, max_speed, max_accel))


def plan_trajectory(
    *plan_args,
    max_step: float = 0.005,
    max_speed: float = 0.005,
    max_accel: float = 0.005,
    smoothing: int = 3,
    check_step: float = CHECK_STEP,
    **plan_kwargs,
) -> TrajectoryPlan:
    """A* (`inflarm_planning.astar.plan`, with ``plan_args`` and ``plan_kwargs``) then
    `make_trajectory` (with the keyword arguments here).

    Raises
    ------
    ValueError
        For bad arguments.
    inflarm_planning.astar.NoPathError
        When no path exists.
    """
    # validate the trajectory arguments before searching
    for name, value, unit, quantity in (('max_step', max_step, 'm', 'length'),
                                        ('max_speed', max_speed, 'm/s', 'speed'),
                                        ('max_accel', max_accel, 'm/s^2', 'acceleration'),
                                        ('check_step', check_step, 'm', 'length')):
        check_positive(name, value, unit, quantity)
    smooth(np.zeros((2, 3)), np.zeros((0, 2, 3)), smoothing)  # validates smoothing
    grid = plan(*plan_args, **plan_kwargs)
    space = grid.free_space
    trajectory = make_trajectory(grid.path, space.obstacles, space.alert_margin,
                                 max_step=max_step, max_speed=max_speed, max_accel=max_accel,
                                 smoothing=smoothing, check_step=check_step)
    return TrajectoryPlan(grid, trajectory)
