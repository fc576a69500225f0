"""The planning grid over the soft arm's work space and its free cells (eq. 5 on every point).

The grid is the lattice of points ``index * resolution`` in ``sra_mount`` that lie inside the
work-space bounds (section 2.2), so the paper's millimetre coordinates are grid points at 10, 5,
2 and 1 mm. A point is *free* if the arm with its end there meets no alert region
(`inflarm_planning.collision.arm_collides`). The free grid depends only on the obstacles, the
alert margin, the resolution and the work space: `free_space` builds it once per such set and
keeps the last few in a cache, so that replanning to new goals costs only the search.
"""

from collections.abc import Iterable
from dataclasses import dataclass
import functools
import math
import time

import numpy as np
import numpy.typing as npt

from inflarm_model.soft_arm import WORKSPACE_POSITIVE, Workspace
from inflarm_model.validation import check_positive
from inflarm_planning.collision import Cuboid, arm_collides, as_cuboids, box_array, check_margin

MAX_CELLS = 120_000_000
"""Largest grid `free_space` accepts: about 11 bytes per cell are needed to build and search it
(the free grid, the search's path costs, parents and closed set), so ~1.3 GB; the positive work
space at 1 mm has 68.4 million points."""

MAX_AXIS_POINTS = 1e7
"""Beyond this many points along an axis a resolution is refused before any count is made."""

BUILD_CHUNK = 1 << 20
"""Grid points tested per vectorized batch while building."""

CACHE_SIZE = 4
"""Free-space grids kept by `free_space` (obstacle sets x resolutions)."""


def check_resolution(resolution: float) -> float:
    """Validate a grid resolution: a finite number > 0 [m]."""
    return check_positive('resolution', resolution, 'm', 'length')


@dataclass(frozen=True)
class Lattice:
    """Grid points ``index * resolution`` inside the work space's bounds.

    Attributes
    ----------
    resolution : float
        Spacing of the points [m].
    first : tuple of 3 int
        Integer coordinates of the grid's first point (its index (0, 0, 0)).
    shape : tuple of 3 int
        Number of points along x, y, z.
    """

    resolution: float
    first: tuple[int, int, int]
    shape: tuple[int, int, int]

    @classmethod
    def over(cls, workspace: Workspace, resolution: float) -> 'Lattice':
        """The lattice of ``resolution`` covering ``workspace``'s bounds."""
        r = check_resolution(resolution)
        low = (-workspace.x_max, -workspace.y_max, workspace.z_min)
        high = (workspace.x_max, workspace.y_max, workspace.z_max)
        if any(not (abs(v) / r < MAX_AXIS_POINTS) for v in low + high):
            raise ValueError(f'resolution {r:g} m is too fine for memory: more than '
                             f'{MAX_AXIS_POINTS:g} grid points along an axis')
        eps = 1e-9  # points on a bound (the paper's millimetres) belong to the grid

        def first_in(v: float) -> int:
            i = math.ceil(v / r - eps)
            return i if i * r >= v - 1e-12 else i + 1

        def last_in(v: float) -> int:
            i = math.floor(v / r + eps)
            return i if i * r <= v + 1e-12 else i - 1

        first = tuple(first_in(v) for v in low)
        last = tuple(last_in(v) for v in high)
        shape = tuple(max(b - a + 1, 0) for a, b in zip(first, last, strict=True))
        return cls(r, first, shape)

    @property
    def size(self) -> int:
        """Number of grid points."""
        return self.shape[0] * self.shape[1] * self.shape[2]

    def points(self, index: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Coordinates [m] of grid indices, shape (..., 3) in and out."""
        return (np.asarray(index) + np.array(self.first)) * self.resolution

    def nearest_index(self, point: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Index of the grid point nearest to ``point`` (may be outside the grid), (..., 3)."""
        p = np.asarray(point, dtype=float)
        return np.rint(p / self.resolution).astype(np.int64) - np.array(self.first)

    def contains(self, index: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether indices lie on the grid, shape (...)."""
        i = np.asarray(index)
        return np.all((i >= 0) & (i < np.array(self.shape)), axis=-1)


@dataclass(frozen=True, eq=False)
class FreeSpace:
    """Free grid points of one obstacle set: where the arm's end may be (eq. (5)).

    Attributes
    ----------
    lattice : Lattice
        The grid.
    obstacles : tuple of Cuboid
        The obstacles (not grown).
    alert_margin : float
        Growth of each obstacle per axis [m].
    workspace : Workspace
        Bounds the grid covers.
    padded : ndarray of uint8, shape (nx + 2, ny + 2, nz + 2)
        1 where the point is free, 0 where it is blocked; a border of blocked cells around the
        grid lets the search step without bounds checks. Read-only.
    build_time_s : float
        Wall time the build took [s].
    """

    lattice: Lattice
    obstacles: tuple[Cuboid, ...]
    alert_margin: float
    workspace: Workspace
    padded: npt.NDArray[np.uint8]
    build_time_s: float

    @property
    def free(self) -> npt.NDArray[np.bool_]:
        """Free grid points, shape ``lattice.shape`` (a read-only view)."""
        return self.padded[1:-1, 1:-1, 1:-1].view(bool)

    @property
    def boxes(self) -> npt.NDArray[np.float64]:
        """The alert regions, shape (K, 2, 3) [m]."""
        return box_array(self.obstacles, self.alert_margin)

    def is_free(self, index: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether grid indices are on the grid and free, shape (...)."""
        i = np.asarray(index, dtype=np.int64)
        inside = self.lattice.contains(i)
        clipped = np.clip(i, 0, np.array(self.lattice.shape) - 1)
        return inside & self.free[clipped[..., 0], clipped[..., 1], clipped[..., 2]]


def check_grid(
    obstacles: tuple[Cuboid, ...], resolution: float, alert_margin: float,
    workspace: Workspace, max_cells: int = MAX_CELLS,
) -> Lattice:
    """Validate a grid request and return its lattice.

    Raises
    ------
    ValueError
        If the resolution is not > 0, the grid would exceed ``max_cells`` points, or the
        resolution is coarser than an alert region (the grid could then step through it).
    """
    r = check_resolution(resolution)
    margin = check_margin(alert_margin)
    lattice = Lattice.over(workspace, r)
    if lattice.size > max_cells:
        finest = (lattice.size / max_cells) ** (1.0 / 3.0) * r
        raise ValueError(
            f'resolution {r:g} m is too fine for memory: {lattice.size:.3g} grid points '
            f'(limit {max_cells:.3g}, ~11 bytes each); use resolution >= {finest:.2g} m')
    if lattice.size == 0:
        raise ValueError(f'resolution {r:g} m leaves no grid point in the work space')
    for k, box in enumerate(obstacles):
        extent = float(np.min(np.subtract(box.max_corner, box.min_corner))) + 2.0 * margin
        if extent < r:
            raise ValueError(
                f'resolution {r:g} m is coarser than the alert region of obstacles[{k}] '
                f'({extent:g} m across): the grid could step through it; use resolution <= '
                f'{extent:g} m or a larger alert_margin')
    return lattice


def build_free_space(
    obstacles: Iterable, resolution: float, alert_margin: float,
    workspace: Workspace = WORKSPACE_POSITIVE, max_cells: int = MAX_CELLS,
) -> FreeSpace:
    """Test every grid point with eq. (5) (uncached; see `free_space`).

    Parameters
    ----------
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
    resolution : float
        Grid spacing [m], > 0.
    alert_margin : float
        Growth of each obstacle per axis [m], >= 0.
    workspace : Workspace
        Bounds of the grid.
    max_cells : int
        Largest grid accepted.

    Returns
    -------
    FreeSpace
    """
    started = time.perf_counter()
    cuboids = as_cuboids(obstacles)
    margin = check_margin(alert_margin)
    lattice = check_grid(cuboids, resolution, margin, workspace, max_cells)
    nx, ny, nz = lattice.shape
    padded = np.zeros((nx + 2, ny + 2, nz + 2), dtype=np.uint8)
    interior = padded[1:-1, 1:-1, 1:-1]
    boxes = box_array(cuboids, margin)
    if len(boxes) == 0:
        interior[...] = 1
    else:
        r = lattice.resolution
        xs, ys, zs = ((np.arange(n) + f) * r for n, f in zip(lattice.shape, lattice.first,
                                                              strict=True))
        plane = np.stack(np.meshgrid(ys, zs, indexing='ij'), axis=-1).reshape(-1, 2)
        slabs = max(1, BUILD_CHUNK // len(plane))
        for i in range(0, nx, slabs):
            x = xs[i:i + slabs]
            points = np.empty((len(x), len(plane), 3))
            points[..., 0] = x[:, None]
            points[..., 1:] = plane
            blocked = arm_collides(points, boxes)
            interior[i:i + slabs] = ~blocked.reshape(len(x), ny, nz)
    padded.setflags(write=False)
    return FreeSpace(lattice, cuboids, margin, workspace, padded,
                     time.perf_counter() - started)


@functools.lru_cache(maxsize=CACHE_SIZE)
def _cached(obstacles: tuple[Cuboid, ...], resolution: float, alert_margin: float,
            workspace: Workspace, max_cells: int) -> FreeSpace:
    return build_free_space(obstacles, resolution, alert_margin, workspace, max_cells)


def free_space(
    obstacles: Iterable, resolution: float, alert_margin: float,
    workspace: Workspace = WORKSPACE_POSITIVE, max_cells: int = MAX_CELLS,
) -> FreeSpace:
    """The free grid of an obstacle set, built once and cached (the last `CACHE_SIZE` kept).

    Same parameters and result as `build_free_space`; a cached grid keeps the
    ``build_time_s`` of its build.
    """
    cuboids = as_cuboids(obstacles)
    margin = check_margin(alert_margin)
    r = check_resolution(resolution)
    return _cached(cuboids, r, margin, workspace, int(max_cells))  # a build error is not cached


def clear_cache() -> None:
    """Forget every cached free grid."""
    _cached.cache_clear()
