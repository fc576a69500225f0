"""A* path planning of the soft arm's end around cuboid obstacles (section 4.1 of 001_...).

``plan(start, goal, obstacles, resolution, alert_margin)`` searches the grid of the work space
(`inflarm_planning.free_space`) with A* (open set, closed set, Fig 9) and returns the grid path,
from the exact start to the exact goal, in ``sra_mount`` [m], with how it was found;
``plan_path`` the path alone.

Neighbours (``connectivity=``): the paper's "eight neighbouring points" are those of a planar
grid, the 3 x 3 square around a point; in 3-D the same square is the 3 x 3 x 3 cube, 26
neighbours (the default). 18 (faces and edges) and 6 (faces) are the smaller neighbourhoods,
with longer paths (the README gives the lengths on the paper's scenario).

Costs (``cost=``):

- ``'length'`` (default): ``f = g + h``, ``g`` the length of the path so far, ``h`` the
  Euclidean distance to the goal. Every step of every neighbourhood is at least as long as the
  Euclidean distance it covers, so ``h`` never overestimates the remaining length and drops by
  at most a step's cost per step (admissible and consistent for 6, 18 and 26 neighbours): the
  path is a shortest grid path of the neighbourhood.
- ``'paper'``: eq. (7), ``P_cur = f_cur + g_cur`` with ``f_cur`` the Manhattan distance from
  the start and ``g_cur`` the Euclidean distance to the goal. We read ``f_cur`` as the
  Manhattan length of the path planned so far (the paper's reason for it: that part of the path
  "has been successfully planned"), which is the Manhattan distance from the start for every
  path that never turns back on an axis. A diagonal step then costs 2 or 3 instead of sqrt(2)
  or sqrt(3): the search minimises the Manhattan length, for which every staircase between two
  points is equally short, so its path is a shortest one only by the tie-breaking. The
  Euclidean ``g_cur`` is admissible and consistent for every neighbourhood (a step's Manhattan
  length is at least its Euclidean length). The README gives both lengths on the paper's
  scenario.

The search is exact for its cost but looks only where it has to: with an upper bound ``C`` of
the path cost, every cell the search expands has ``|n - start| + |n - goal| <= C`` (an
ellipsoid), so it runs on the grid cropped to that ellipsoid's bounding box, starting from 1.5
times the obstacle-free cost and widening to the cost it finds (or doubling when it finds none)
until the crop is known to contain the optimum. Steps do not cut corners (see
`inflarm_planning.grid_search.GUARD_OFFSETS`): with every alert region at least a cell wide
(`check_grid` enforces it), the end stays out of the alert regions along every step, not only at
grid points; the axes are checked at the grid points (see ``README.md`` for the bound between).
"""

from collections.abc import Iterable
from dataclasses import dataclass
import itertools
import math
import time

import numpy as np
import numpy.typing as npt

from inflarm_model.soft_arm import WORKSPACE_POSITIVE, Workspace, check_in_workspace
from inflarm_model.validation import check_vector
from inflarm_planning.collision import (
    CHECK_STEP,
    Cuboid,
    arm_collides,
    as_cuboids,
    check_margin,
    describe_collision,
    motions_collide,
)
from inflarm_planning.free_space import MAX_CELLS, FreeSpace, check_resolution, free_space
from inflarm_planning.grid_search import (
    STEP_COSTS,
    GridPath,
    astar_grid,
    check_connectivity,
    grid_distance,
    kind_costs,
)

__all__ = ['COSTS', 'Cuboid', 'NoPathError', 'PlanResult', 'plan', 'plan_path']

COSTS = STEP_COSTS
"""Step costs [cells] of the two costs: path length (default), Manhattan length (eq. (7))."""

INITIAL_BOUND = 1.5
"""First crop of the search: the ellipsoid for 1.5 times the obstacle-free path cost."""


class NoPathError(RuntimeError):
    """No collision-free path exists between start and goal on this grid.

    Attributes
    ----------
    reason : str
        ``'outside_workspace'``, ``'start_blocked'``, ``'goal_blocked'`` or
        ``'no_connection'`` (the open set emptied before the goal was reached).
    """

    REASONS = ('outside_workspace', 'start_blocked', 'goal_blocked', 'no_connection')

    def __init__(self, message: str, reason: str) -> None:
        if reason not in self.REASONS:
            raise ValueError(f'expected reason in {self.REASONS}, got {reason!r}')
        super().__init__(message, reason)
        self.reason = reason

    def __str__(self) -> str:
        return self.args[0]


@dataclass(frozen=True)
class PlanResult:
    """A planned grid path and how it was found.

    Attributes
    ----------
    path : ndarray, shape (N, 3)
        From the exact start, through grid points, to the exact goal, ``sra_mount`` [m].
    cells : ndarray of int64, shape (N', 3)
        Grid indices of the grid points of the path.
    cost : str
        The cost used, a key of `COSTS`.
    connectivity : int
        The neighbourhood searched: 6, 18 or 26.
    expanded : int
        Cells expanded by the search (all crops together).
    searches : int
        Crops searched (1 unless the first crop had to be widened).
    search_time_s : float
        Wall time of snapping and searching, excluding the free-space build [s].
    free_space : FreeSpace
        The free grid searched (with its ``build_time_s``).
    """

    path: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int64]
    cost: str
    connectivity: int
    expanded: int
    searches: int
    search_time_s: float
    free_space: FreeSpace

    @property
    def length(self) -> float:
        """Length of `path` [m]."""
        return float(np.linalg.norm(np.diff(self.path, axis=0), axis=1).sum())


def _outside(point: np.ndarray, workspace: Workspace) -> bool:
    x, y, z = (float(v) for v in point)
    return not (abs(x) <= workspace.x_max and abs(y) <= workspace.y_max
                and workspace.z_min <= z <= workspace.z_max)


def _grid_cell(space: FreeSpace, point: np.ndarray, name: str, reason: str) -> np.ndarray:
    """The grid point a path leaves from or arrives at, for an end point ``point`` (3,).

    ``point`` itself if it is a free grid point; otherwise the nearest free corner of the grid
    cell around it that the end reaches in a straight line without collision.

    Raises
    ------
    NoPathError
        If the arm with its end at ``point`` collides (eq. (5)), or no corner is in reach.
    """
    lattice = space.lattice
    r = lattice.resolution
    index = [round(float(v) / r) - f for v, f in zip(point, lattice.first, strict=True)]
    on_grid = all(abs((i + f) * r - float(v)) < 1e-9 and 0 <= i < n for i, f, v, n in
                  zip(index, lattice.first, point, lattice.shape, strict=True))
    if on_grid:
        if space.free[tuple(index)]:
            return np.array(index, dtype=np.int64)
        blocked = True
    else:
        blocked = bool(arm_collides(point, space.boxes))
    if blocked:
        why = describe_collision(point, space.obstacles, space.alert_margin)
        raise NoPathError(f'{name} {np.round(point, 4).tolist()} m is not free: {why}', reason)
    low = np.floor(point / r + 1e-9).astype(np.int64) - np.array(lattice.first)
    corners = np.unique(np.array([low + np.array(c) for c in itertools.product((0, 1), repeat=3)]),
                        axis=0)
    corners = corners[space.is_free(corners)]
    if len(corners):
        points = lattice.points(corners)
        corners = corners[~motions_collide(point, points, space.boxes, CHECK_STEP)]
    if not len(corners):
        raise NoPathError(
            f'{name} {np.round(point, 4).tolist()} m has no free grid point in reach at '
            f'resolution {r:g} m (it is too close to an alert region); use a finer resolution',
            reason)
    distance = np.linalg.norm(lattice.points(corners) - point, axis=1)
    return corners[np.argmin(distance)]


def _free_cost(delta: np.ndarray, cost: str, connectivity: int) -> float:
    """Cost of the cheapest obstacle-free grid path over ``delta`` cells."""
    one, two, three = kind_costs(COSTS[cost])
    return float(grid_distance(*(int(v) for v in delta), connectivity, one, two, three))


def _ellipsoid_box(start: np.ndarray, goal: np.ndarray, bound: float, shape: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Grid-clipped bounding box (inclusive) of {n : |n - start| + |n - goal| <= bound}."""
    delta = [float(b - a) for a, b in zip(start, goal, strict=True)]
    distance = math.sqrt(sum(d * d for d in delta))
    a2 = (max(bound, distance) / 2.0) ** 2
    b2 = max(a2 - distance * distance / 4.0, 0.0)
    low, high = [], []
    for axis in range(3):
        u2 = (delta[axis] / distance) ** 2 if distance > 0 else 0.0
        half = math.sqrt(a2 * u2 + b2 * (1.0 - u2))
        centre = (float(start[axis]) + float(goal[axis])) / 2.0
        low.append(max(math.floor(centre - half) - 1, 0))
        high.append(min(math.ceil(centre + half) + 1, int(shape[axis]) - 1))
    return np.array(low), np.array(high)


def _search(space: FreeSpace, start: np.ndarray, goal: np.ndarray, cost: str, connectivity: int
            ) -> tuple[GridPath, int]:
    shape = np.array(space.lattice.shape)
    step_cost = COSTS[cost]
    bound = INITIAL_BOUND * _free_cost(goal - start, cost, connectivity)
    expanded, searches = 0, 0
    while True:
        low, high = _ellipsoid_box(start, goal, bound, shape)
        whole = bool(np.all(low == 0) and np.all(high == shape - 1))
        crop = np.zeros(tuple(high - low + 3), dtype=np.uint8)
        crop[1:-1, 1:-1, 1:-1] = space.padded[low[0] + 1:high[0] + 2, low[1] + 1:high[1] + 2,
                                              low[2] + 1:high[2] + 2]
        result = astar_grid(crop, start - low, goal - low, step_cost, connectivity)
        expanded += result.expanded
        searches += 1
        if result.found and (result.cost <= bound or whole):
            return GridPath(result.cells + low, result.cost, expanded), searches
        if not result.found and whole:
            return GridPath(result.cells, result.cost, expanded), searches
        # a path costlier than the bound, or none in the crop: widen to what is now known
        bound = result.cost if result.found else 2.0 * bound


def plan(
    start: npt.ArrayLike,
    goal: npt.ArrayLike,
    obstacles: Iterable = (),
    resolution: float = 0.005,
    alert_margin: float = 0.01,
    *,
    cost: str = 'length',
    connectivity: int = 26,
    workspace: Workspace = WORKSPACE_POSITIVE,
    max_cells: int = MAX_CELLS,
) -> PlanResult:
    """Plan a collision-free path of the soft arm's end by A* on the grid (section 4.1) and
    report how it was found.

    Parameters
    ----------
    start, goal : array-like, shape (3,)
        End points in ``sra_mount`` [m]; different.
    obstacles : iterable of Cuboid or inflarm_msgs_json.Cuboid
        Axis-aligned obstacles in ``sra_mount``.
    resolution : float
        Grid spacing [m], > 0; at most every alert region's width.
    alert_margin : float
        Growth of each obstacle per axis [m], >= 0 (the paper: more than half the actuator
        width). The end stays out of the grown boxes and the PEA axes do not cross them.
    cost : {'length', 'paper'}
        Path length (default), or eq. (7) (see the module docstring).
    connectivity : {6, 18, 26}
        Neighbours of a grid point: across the faces (6), faces and edges (18), or the whole
        3 x 3 x 3 cube (26, the default: the paper's eight neighbours of a planar grid in 3-D,
        and the shortest paths).
    workspace : Workspace
        Bounds of the grid (default: the positive-pressure work space, section 2.2).
    max_cells : int
        Largest grid accepted (memory).

    Returns
    -------
    PlanResult
        Its ``path``, shape (N, 3), goes from ``start`` through grid points to ``goal`` [m],
        ``sra_mount``. The free grid is built once per obstacle set and resolution and cached
        (`free_space`).

    Raises
    ------
    ValueError
        Non-finite or misshapen start or goal, start == goal, an unknown cost, a
        connectivity other than 6, 18 or 26, a bad obstacle, a negative margin, a
        resolution <= 0, too fine for ``max_cells`` or coarser than an alert region.
    NoPathError
        Start or goal outside the work space, inside an alert region, with an axis across
        one, or with no free grid point in reach; or no connection (the open set emptied).
    """
    start = check_vector('start', start, 3, 'm')
    goal = check_vector('goal', goal, 3, 'm')
    if np.array_equal(start, goal):
        raise ValueError(f'expected start != goal, both are {start.tolist()}')
    if cost not in COSTS:
        raise ValueError(f'expected cost in {sorted(COSTS)}, got {cost!r}')
    connectivity = check_connectivity(connectivity)
    cuboids = as_cuboids(obstacles)
    margin = check_margin(alert_margin)
    resolution = check_resolution(resolution)
    space = free_space(cuboids, resolution, margin, workspace, max_cells)
    started = time.perf_counter()
    for name, point in (('start', start), ('goal', goal)):
        if _outside(point, workspace):
            try:
                check_in_workspace(point, workspace, name)  # says which bound
            except ValueError as err:
                raise NoPathError(str(err), 'outside_workspace') from None
    first = _grid_cell(space, start, 'start', 'start_blocked')
    last = _grid_cell(space, goal, 'goal', 'goal_blocked')
    if np.array_equal(first, last):
        grid = GridPath(first[None, :], 0.0, 0)
        searches = 0
    else:
        grid, searches = _search(space, first, last, cost, connectivity)
    if not grid.found:
        raise NoPathError(
            f'no connection from start {np.round(start, 4).tolist()} m to goal '
            f'{np.round(goal, 4).tolist()} m: the open set emptied after {grid.expanded} cells '
            f'(obstacles and alert regions close off the goal at resolution {resolution:g} m)',
            'no_connection')
    points = space.lattice.points(grid.cells)
    same = 1e-9  # [m]: a start or goal on a grid point is not repeated
    head = points[1:] if np.linalg.norm(points[0] - start) < same else points
    if len(head) and np.linalg.norm(head[-1] - goal) < same:
        head = head[:-1]
    path = np.vstack([start, head, goal])
    return PlanResult(path, grid.cells, cost, connectivity, grid.expanded, searches,
                      time.perf_counter() - started, space)


def plan_path(*args, **kwargs) -> npt.NDArray[np.float64]:
    """The path of `plan` (same arguments), shape (N, 3) [m], ``sra_mount``."""
    return plan(*args, **kwargs).path
