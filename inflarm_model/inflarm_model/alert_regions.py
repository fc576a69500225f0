"""Alert regions of cuboid obstacles and their repulsive term (4.3.2 of 001_b59ad71c956a1751).

An obstacle's *alert region* is the box grown by the alert margin on each side of every axis
(section 4.1: more than half the actuator width). The planner keeps the end and the actuators'
axes out of it (``inflarm_planning``); the path follower pushes the end back out when it enters
one anyway (``inflarm_control.path_following``): "the control algorithm adopted the repulsive
effect to keep the SRA's end out of the alert region". Both use `repulsive_offset`, which is
here, below both, because the algorithm packages do not import each other.

Regions are arrays of shape ``(K, 2, 3)`` in ``sra_mount`` [m]: ``regions[k, 0]`` the min
corner, ``regions[k, 1]`` the max corner (already grown).
"""

import numpy as np
import numpy.typing as npt

import inflarm_msgs_json


def check_regions(regions: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Validate boxes: shape (K, 2, 3), finite, min corner <= max corner [m].

    Raises
    ------
    ValueError
        Naming what is wrong.
    """
    b = np.asarray(regions, dtype=float)
    if b.ndim != 3 or b.shape[1:] != (2, 3):
        raise ValueError(f'expected regions of shape (K, 2, 3), got {b.shape}')
    if not np.all(np.isfinite(b)):
        raise ValueError('expected finite region corners [m]')
    if np.any(b[:, 0] > b[:, 1]):
        k = int(np.flatnonzero(np.any(b[:, 0] > b[:, 1], axis=-1))[0])
        raise ValueError(f'expected min corner <= max corner, region {k} is {b[k].tolist()}')
    return b


def grow_boxes(boxes: npt.ArrayLike, margin: float) -> npt.NDArray[np.float64]:
    """Boxes ``(K, 2, 3)`` grown by ``margin`` [m] (>= 0) on each side of every axis."""
    b = check_regions(boxes).copy()
    m = float(margin)
    if not (np.isfinite(m) and m >= 0.0):
        raise ValueError(f'expected margin >= 0 m, got {margin!r}')
    b[:, 0] -= m
    b[:, 1] += m
    return b


def repulsive_offset(end_point: npt.ArrayLike, regions: npt.ArrayLike
                     ) -> npt.NDArray[np.float64]:
    """Repulsive term of section 4.3.2: the displacement that takes the end out of the regions.

    For each region containing the end (its surface included), the shortest way out: along the
    outward normal of the region's nearest face, with magnitude the end's depth below that face
    (the distance from the end to the region's surface), so that ``end + offset`` lies on the
    surface. Offsets of several regions add up; outside every region the offset is 0.

    Parameters
    ----------
    end_point : array-like, shape (3,) or (..., 3)
        Measured end point in ``sra_mount`` [m].
    regions : array-like, shape (K, 2, 3)
        Alert regions (obstacles grown by the alert margin) [m].

    Returns
    -------
    offset : ndarray, shape (3,) or (..., 3)
        Displacement [m]; its norm is the depth into the region (summed over regions).
    """
    p = np.asarray(end_point, dtype=float)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(f'expected end_point of shape (..., 3), got {p.shape}')
    if not np.all(np.isfinite(p)):
        raise ValueError('expected finite end_point [m]')
    offset = np.zeros(p.shape)
    for low, high in check_regions(regions):
        below, above = p - low, high - p  # depth under the low and high face of each axis
        inside = np.all((below >= 0.0) & (above >= 0.0), axis=-1)
        depths = np.concatenate([below, above], axis=-1)  # (..., 6): -x, -y, -z, +x, +y, +z
        face = np.argmin(depths, axis=-1)
        depth = np.take_along_axis(depths, face[..., None], axis=-1)[..., 0]
        normal = np.zeros(p.shape)
        np.put_along_axis(normal, (face % 3)[..., None],
                          np.where(face < 3, -1.0, 1.0)[..., None], axis=-1)
        offset += np.where(inside[..., None], normal * depth[..., None], 0.0)
    return offset


def regions_of(obstacles: inflarm_msgs_json.ObstacleSet) -> npt.NDArray[np.float64]:
    """The alert regions of an ObstacleSet message: its boxes grown by its ``alert_margin``.

    Returns
    -------
    regions : ndarray, shape (K, 2, 3)
        In the message's frame [m].
    """
    if not isinstance(obstacles, inflarm_msgs_json.ObstacleSet):
        raise ValueError(f'expected an ObstacleSet, got {type(obstacles).__name__}')
    boxes = np.array([[box.min, box.max] for box in obstacles.obstacles], dtype=float)
    return grow_boxes(boxes.reshape(-1, 2, 3), obstacles.alert_margin)
