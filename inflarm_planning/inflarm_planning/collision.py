"""Collision model of the soft arm against cuboid obstacles (section 4.1 of 001_b59ad71c956a1751).

Eq. (5): the arm, with its end at ``p``, collides with an obstacle if ``p`` lies in it or if the
space of PEA1 or PEA2 meets it. As in the paper, the actuators are reduced to their central axes
(``inflarm_model.soft_arm.central_axes``: PEA1 from the mount to the PBA at ``(0, 0, l1)``, PEA2
from there to the end, ``l1`` from eq. (6)) and their cross-section is accounted for by growing
each obstacle per axis by ``alert_margin`` (the *alert region*, larger than half the actuator
width). Every test here is on the grown boxes; the obstacles themselves only matter for the
distances of Fig 12 and for the repulsive term of section 4.3.2
(`inflarm_model.alert_regions`, shared with the path follower).

All functions broadcast over leading dimensions of the points and work in ``sra_mount`` [m].
Boxes are passed as arrays of shape ``(K, 2, 3)`` (``boxes[k, 0]`` the min corner, ``boxes[k,
1]`` the max corner), made from `Cuboid` objects by `box_array`.
"""

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from inflarm_model import alert_regions
from inflarm_model.soft_arm import pea_length_from_end_point
from inflarm_model.validation import check_batch, check_positive, check_vector
import inflarm_msgs_json

SEGMENT_CHUNK = 1 << 18
"""Segments tested per vectorized batch (bounds the temporaries to a few tens of MB)."""

CHECK_STEP = 0.001
"""Default spacing of the poses `motions_collide` samples along a motion [m]."""


@dataclass(frozen=True)
class Cuboid:
    """Axis-aligned box obstacle in ``sra_mount``, given by two extreme corners.

    The planning counterpart of the ``inflarm_msgs_json.Cuboid`` message (fields ``min``,
    ``max``, ``name``): `from_message` and `to_message` convert losslessly, and every planning
    function accepts either.

    Attributes
    ----------
    min_corner : tuple of 3 float
        Corner with the smallest coordinates [m].
    max_corner : tuple of 3 float
        Corner with the largest coordinates [m]; ``min_corner <= max_corner`` on every axis (a
        flat box is allowed: its alert region still has a volume).
    name : str
        Label for messages and markers.

    Raises
    ------
    ValueError
        If a corner is not 3 finite numbers or ``min_corner > max_corner`` on an axis.
    """

    min_corner: tuple[float, float, float]
    max_corner: tuple[float, float, float]
    name: str = ''

    def __post_init__(self) -> None:
        low = check_vector('min_corner', self.min_corner, 3, 'm')
        high = check_vector('max_corner', self.max_corner, 3, 'm')
        for axis in range(3):
            if low[axis] > high[axis]:
                raise ValueError(
                    f'expected min_corner <= max_corner on every axis, got '
                    f'{"xyz"[axis]}: {float(low[axis])!r} > {float(high[axis])!r}')
        if not isinstance(self.name, str):
            raise ValueError(f'expected name to be a str, got {type(self.name).__name__}')
        # frozen dataclass: store the normalised values (hashable tuples of floats)
        object.__setattr__(self, 'min_corner', tuple(float(v) for v in low))
        object.__setattr__(self, 'max_corner', tuple(float(v) for v in high))

    @classmethod
    def from_message(cls, box: inflarm_msgs_json.Cuboid) -> 'Cuboid':
        """The planning box of an ``inflarm_msgs_json.Cuboid`` message."""
        return cls(box.min, box.max, box.name)

    def to_message(self) -> inflarm_msgs_json.Cuboid:
        """This box as an ``inflarm_msgs_json.Cuboid`` message."""
        return inflarm_msgs_json.Cuboid(min=self.min_corner, max=self.max_corner, name=self.name)

    def grown(self, margin: float) -> 'Cuboid':
        """The box grown by ``margin`` [m] on each side of every axis (the alert region)."""
        margin = check_margin(margin)
        return Cuboid(tuple(v - margin for v in self.min_corner),
                      tuple(v + margin for v in self.max_corner), self.name)

    @property
    def bounds(self) -> npt.NDArray[np.float64]:
        """``[min_corner, max_corner]``, shape (2, 3) [m]."""
        return np.array([self.min_corner, self.max_corner])


def check_margin(alert_margin: float, name: str = 'alert_margin') -> float:
    """Validate an alert margin: a finite number >= 0 [m]."""
    try:
        margin = float(alert_margin)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} to be a number [m], got {alert_margin!r}') from None
    if not np.isfinite(margin) or margin < 0.0:
        raise ValueError(f'expected {name} >= 0 m, got {alert_margin!r}')
    return margin


def as_cuboids(obstacles: Iterable, name: str = 'obstacles') -> tuple[Cuboid, ...]:
    """Coerce obstacles to a tuple of `Cuboid`.

    Parameters
    ----------
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
        The boxes; an ``inflarm_msgs_json.ObstacleSet`` gives its ``obstacles`` field.
    name : str
        What the obstacles are, for the error message.

    Returns
    -------
    tuple of Cuboid

    Raises
    ------
    ValueError
        Naming the first entry that is not a box.
    """
    if isinstance(obstacles, inflarm_msgs_json.ObstacleSet):
        obstacles = obstacles.obstacles
    if isinstance(obstacles, (Cuboid, inflarm_msgs_json.Cuboid)):
        obstacles = (obstacles,)
    try:
        items = tuple(obstacles)
    except TypeError:
        raise ValueError(
            f'expected {name} to be a sequence of Cuboid, got {type(obstacles).__name__}'
        ) from None
    result = []
    for i, box in enumerate(items):
        if isinstance(box, Cuboid):
            result.append(box)
        elif isinstance(box, inflarm_msgs_json.Cuboid):
            result.append(Cuboid.from_message(box))
        else:
            raise ValueError(f'expected {name}[{i}] to be a Cuboid, got {type(box).__name__}')
    return tuple(result)


def box_array(obstacles: Iterable, margin: float = 0.0) -> npt.NDArray[np.float64]:
    """Corners of the obstacles grown by ``margin``, shape (K, 2, 3) [m].

    Parameters
    ----------
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
    margin : float
        Growth per side and axis [m], >= 0 (the alert margin; 0 for the obstacles themselves).
    """
    margin = check_margin(margin, 'margin')
    boxes = [c.bounds for c in as_cuboids(obstacles)]
    return alert_regions.grow_boxes(np.array(boxes, dtype=float).reshape(-1, 2, 3), margin)


def _check_boxes(boxes: npt.ArrayLike) -> npt.NDArray[np.float64]:
    b = np.asarray(boxes, dtype=float)
    if b.ndim != 3 or b.shape[1:] != (2, 3):
        raise ValueError(f'expected boxes of shape (K, 2, 3), got {b.shape}')
    return b


def points_in_boxes(points: npt.ArrayLike, boxes: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether each point lies in (or on the surface of) any of the boxes.

    Parameters
    ----------
    points : array-like, shape (..., 3)
        Points [m].
    boxes : array-like, shape (K, 2, 3)
        Box corners [m] (`box_array`).

    Returns
    -------
    inside : ndarray of bool, shape (...)
    """
    p = check_batch('points', points, 3, 'm')
    b = _check_boxes(boxes)
    inside = np.zeros(p.shape[:-1], dtype=bool)
    for low, high in b:
        inside |= np.all((p >= low) & (p <= high), axis=-1)
    return inside


def _columns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, y, z of points (M, 3) as contiguous 1-D arrays (numpy is much faster on these)."""
    return tuple(np.ascontiguousarray(points[:, axis]) for axis in range(3))


def _hit_columns(a: tuple, d: tuple, boxes: np.ndarray) -> np.ndarray:
    """Slab test of segments ``a + t d``, t in [0, 1], against closed boxes, any of them.

    ``a`` and ``d`` are (x, y, z) tuples of 1-D arrays (or scalars) broadcasting to (M,).
    """
    shape = np.broadcast_shapes(*(np.shape(c) for c in a + d))
    hit = np.zeros(shape, dtype=bool)
    for low, high in boxes:
        enter = np.zeros(shape)
        leave = np.ones(shape)
        for axis in range(3):
            start, step = a[axis], d[axis]
            with np.errstate(divide='ignore', invalid='ignore'):
                t_low = (low[axis] - start) / step
                t_high = (high[axis] - start) / step
            parallel = np.asarray(step == 0.0)
            if parallel.any():  # within the slab for every t (-inf, inf) or for none (inf, inf)
                inside = (start >= low[axis]) & (start <= high[axis])
                t_low = np.where(parallel, np.where(inside, -np.inf, np.inf), t_low)
                t_high = np.where(parallel, np.inf, t_high)
            np.maximum(enter, np.minimum(t_low, t_high), out=enter)
            np.minimum(leave, np.maximum(t_low, t_high), out=leave)
        hit |= enter <= leave
    return hit


def segments_hit_boxes(
    a: npt.ArrayLike, b: npt.ArrayLike, boxes: npt.ArrayLike
) -> npt.NDArray[np.bool_]:
    """Whether each segment from ``a`` to ``b`` meets any of the closed boxes (slab method).

    Exact for straight segments; a segment that only touches a box's surface counts as meeting
    it.

    Parameters
    ----------
    a, b : array-like, shape (..., 3), broadcastable
        Segment end points [m].
    boxes : array-like, shape (K, 2, 3)
        Box corners [m].

    Returns
    -------
    hit : ndarray of bool, broadcast shape (...)
    """
    a = check_batch('a', a, 3, 'm')
    b = check_batch('b', b, 3, 'm')
    boxes = _check_boxes(boxes)
    a, b = np.broadcast_arrays(a, b)
    shape = a.shape[:-1]
    a = a.reshape(-1, 3)
    b = b.reshape(-1, 3)
    hit = np.zeros(len(a), dtype=bool)
    for first in range(0, len(a), SEGMENT_CHUNK):
        part = slice(first, first + SEGMENT_CHUNK)
        start = _columns(a[part])
        step = tuple(e - s for e, s in zip(_columns(b[part]), start, strict=True))
        hit[part] = _hit_columns(start, step, boxes)
    return hit.reshape(shape)


@dataclass(frozen=True)
class ArmContacts:
    """Which parts of the arm meet the boxes, per end point (the three cases of eq. (5)).

    Attributes
    ----------
    end : ndarray of bool, shape (...)
        The end point lies in a box.
    pea1 : ndarray of bool, shape (...)
        PEA1's central axis (mount to PBA) meets a box.
    pea2 : ndarray of bool, shape (...)
        PEA2's central axis (PBA to end) meets a box (true whenever ``end`` is).
    """

    end: npt.NDArray[np.bool_]
    pea1: npt.NDArray[np.bool_]
    pea2: npt.NDArray[np.bool_]

    @property
    def any(self) -> npt.NDArray[np.bool_]:
        """The arm collides (eq. (5)), shape (...)."""
        return self.end | self.pea1 | self.pea2


def _axis_hits(p: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether the PEA1 and the PEA2 axis meet any box, for end points ``p`` (M, 3).

    The axes are those of ``inflarm_model.soft_arm.central_axes`` (PEA1 from the mount to
    ``(0, 0, l1)``, PEA2 from there to the end, ``l1`` by eq. (6)), kept as coordinate columns:
    the tests check that both give the same segments.
    """
    pea1 = np.zeros(len(p), dtype=bool)
    pea2 = np.zeros(len(p), dtype=bool)
    for first in range(0, len(p), SEGMENT_CHUNK):
        part = slice(first, first + SEGMENT_CHUNK)
        x, y, z = _columns(p[part])
        l1 = np.atleast_1d(pea_length_from_end_point(p[part]))
        pea1[part] = _hit_columns((0.0, 0.0, 0.0), (0.0, 0.0, l1), boxes)
        pea2[part] = _hit_columns((0.0, 0.0, l1), (x, y, z - l1), boxes)
    return pea1, pea2


def arm_contacts(end_points: npt.ArrayLike, boxes: npt.ArrayLike) -> ArmContacts:
    """Eq. (5) case by case: end inside a box, PEA1 or PEA2 axis meeting a box.

    Parameters
    ----------
    end_points : array-like, shape (..., 3)
        End points in ``sra_mount`` [m], ``z > 0``.
    boxes : array-like, shape (K, 2, 3)
        Alert regions (obstacles grown by the alert margin, `box_array`) [m].

    Returns
    -------
    ArmContacts
    """
    p = check_batch('end_points', end_points, 3, 'm')
    b = _check_boxes(boxes)
    pea1, pea2 = _axis_hits(p.reshape(-1, 3), b)
    return ArmContacts(end=points_in_boxes(p, b), pea1=pea1.reshape(p.shape[:-1]),
                       pea2=pea2.reshape(p.shape[:-1]))


def arm_collides(end_points: npt.ArrayLike, boxes: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Eq. (5): whether the arm with its end at each point meets any box.

    The end point is the far end of PEA2's axis, so "the end lies in a box" is part of the
    PEA2 test.

    Parameters
    ----------
    end_points : array-like, shape (..., 3)
        End points in ``sra_mount`` [m], ``z > 0``.
    boxes : array-like, shape (K, 2, 3)
        Alert regions (obstacles grown by the alert margin, `box_array`) [m].

    Returns
    -------
    collides : ndarray of bool, shape (...)
    """
    p = check_batch('end_points', end_points, 3, 'm')
    pea1, pea2 = _axis_hits(p.reshape(-1, 3), _check_boxes(boxes))
    return (pea1 | pea2).reshape(p.shape[:-1])


def motions_collide(
    a: npt.ArrayLike, b: npt.ArrayLike, boxes: npt.ArrayLike, step: float
) -> npt.NDArray[np.bool_]:
    """Whether the arm meets any box while its end moves straight from ``a`` to ``b``.

    The end's own path is tested exactly (`segments_hit_boxes`); the PEA axes (eq. (5)) at
    end positions no more than ``step`` apart along the motion, both ends included. Between two
    samples every point of the axes moves no farther than the end does (in the positive-pressure
    work space the PBA height ``l1`` changes by less than 0.71 m per metre of end motion, see the
    tests), so an axis missed between samples reaches at most ``step / 2`` into an alert
    region: never into the obstacle while ``step / 2`` is below the alert margin.

    Parameters
    ----------
    a, b : array-like, shape (M, 3) or (3,)
        Start and end of each motion of the end point [m], broadcastable.
    boxes : array-like, shape (K, 2, 3)
        Alert regions [m] (`box_array`).
    step : float
        Largest spacing of the sampled poses [m], > 0.

    Returns
    -------
    collides : ndarray of bool, shape (M,) (or () for single points)
    """
    a = check_batch('a', a, 3, 'm')
    b = check_batch('b', b, 3, 'm')
    boxes = _check_boxes(boxes)
    step = check_positive('step', step, 'm', 'length')
    a, b = np.broadcast_arrays(a, b)
    shape = a.shape[:-1]
    a = a.reshape(-1, 3)
    b = b.reshape(-1, 3)
    hit = segments_hit_boxes(a, b, boxes)
    counts = np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(a)), counts)
    first = np.cumsum(counts) - counts
    fraction = (np.arange(counts.sum()) - first[owner]) / np.maximum(counts[owner] - 1, 1)
    samples = a[owner] + fraction[:, None] * (b - a)[owner]
    hit |= np.bincount(owner, weights=arm_collides(samples, boxes), minlength=len(a)) > 0
    return hit.reshape(shape)


def describe_collision(
    end_point: npt.ArrayLike, obstacles: Iterable, alert_margin: float
) -> str | None:
    """Why the arm with its end at ``end_point`` is not free, or None if it is.

    Parameters
    ----------
    end_point : array-like, shape (3,)
        End point in ``sra_mount`` [m].
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
    alert_margin : float
        Growth of each obstacle per axis [m].

    Returns
    -------
    str or None
        E.g. ``"the end is inside the alert region of obstacle 0 'box'"``; the first obstacle
        (in order) that the arm meets is named.
    """
    p = check_vector('end_point', end_point, 3, 'm')
    cuboids = as_cuboids(obstacles)
    boxes = box_array(cuboids, alert_margin)
    for k, cuboid in enumerate(cuboids):
        contacts = arm_contacts(p, boxes[k:k + 1])
        label = f'obstacle {k}' + (f" '{cuboid.name}'" if cuboid.name else '')
        inside_obstacle = bool(points_in_boxes(p, box_array([cuboid])))
        if contacts.end:
            where = 'inside' if inside_obstacle else 'inside the alert region of'
            return f'the end is {where} {label} (alert margin {alert_margin:.3f} m)'
        if contacts.pea1:
            return f'the PEA1 axis crosses the alert region of {label}'
        if contacts.pea2:
            return f'the PEA2 axis crosses the alert region of {label}'
    return None


def distance_to_boxes(points: npt.ArrayLike, boxes: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Euclidean distance from each point to the nearest box (0 on or inside one) [m].

    Parameters
    ----------
    points : array-like, shape (..., 3)
        Points [m].
    boxes : array-like, shape (K, 2, 3), K >= 1
        Box corners [m].

    Returns
    -------
    distance : ndarray, shape (...)
    """
    p = check_batch('points', points, 3, 'm')
    b = _check_boxes(boxes)
    if len(b) == 0:
        raise ValueError('expected at least one box')
    gap = np.maximum(np.maximum(b[:, 0] - p[..., None, :], p[..., None, :] - b[:, 1]), 0.0)
    return np.linalg.norm(gap, axis=-1).min(axis=-1)


def repulsive_offset(
    end_point: npt.ArrayLike, obstacles: Iterable, alert_margin: float
) -> npt.NDArray[np.float64]:
    """Repulsive term of section 4.3.2 for obstacles given as cuboids: the displacement that
    takes the end out of their alert regions.

    `inflarm_model.alert_regions.repulsive_offset` (the one implementation, which the path
    follower of ``inflarm_control`` applies) on the obstacles grown by ``alert_margin``: for
    each alert region containing the end, the shortest way out, along the outward normal of its
    nearest face, with magnitude the end's depth below that face; offsets of several regions
    add up; 0 outside every region.

    Parameters
    ----------
    end_point : array-like, shape (3,) or (..., 3)
        Measured end point in ``sra_mount`` [m].
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
    alert_margin : float
        Growth of each obstacle per axis [m], >= 0.

    Returns
    -------
    offset : ndarray, shape (3,) or (..., 3)
        Displacement [m]; its norm is the depth into the alert region (summed over regions).
    """
    p = check_batch('end_point', end_point, 3, 'm')
    return alert_regions.repulsive_offset(p, box_array(obstacles, alert_margin))
