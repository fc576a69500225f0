"""A* over a padded free grid, compiled with numba (the search kernel of `astar`).

A cell's neighbours are those of one of three neighbourhoods (`CONNECTIVITIES`): the 6 across
its faces, the 18 across its faces and edges, or all 26 of the 3 x 3 x 3 cube around it. The
steps and their costs come from here only: `MOVES` lists the 26, `neighbours` picks a
neighbourhood's among them, `STEP_COSTS` gives each step's cost, `grid_distance` the cost of the
cheapest obstacle-free path (the planner's first crop).

The grid is a flat ``uint8`` array in C order of shape ``(nx + 2, ny + 2, nz + 2)`` whose
border cells are blocked (0), so a step never leaves the array. Costs are in cells; the caller
scales them by the resolution.

The kernel is plain A* with an open set (a binary heap with lazy deletion) and a closed set:
``f = g + h`` with ``g`` the cost of the path so far (the sum of the step costs it is given)
and ``h`` the Euclidean distance to the goal, admissible and consistent for every neighbourhood
and both costs (a step costs at least its Euclidean length). It releases the GIL
(``nogil``), so a node can run it in a worker thread while its executor keeps spinning, and
numba caches the compiled code on disk (``cache=True``): only the first call on a machine pays
the ~1-2 s compilation.
"""

from dataclasses import dataclass
import itertools

import numba
import numpy as np
import numpy.typing as npt

MOVES = np.array([m for m in itertools.product((-1, 0, 1), repeat=3) if any(m)],
                 dtype=np.int64)
"""The 26 steps to the neighbours of a cell, shape (26, 3)."""

STEP_LENGTH = np.linalg.norm(MOVES, axis=1)
"""Euclidean length of each step [cells]: 1, sqrt(2) or sqrt(3)."""

STEP_MANHATTAN = np.abs(MOVES).sum(axis=1).astype(float)
"""Manhattan length of each step [cells]: 1, 2 or 3."""

STEP_COSTS = {'length': STEP_LENGTH, 'paper': STEP_MANHATTAN}
"""Cost of each step of `MOVES` [cells] per cost: its length (default), or its Manhattan length
(eq. (7) of 001_...: ``f_cur``, the Manhattan length of the path planned so far)."""

STEP_KIND = np.abs(MOVES).sum(axis=1)
"""Coordinates each step of `MOVES` changes: 1 along an axis, 2 in a plane, 3 across a cube."""

CONNECTIVITIES = (6, 18, 26)
"""The neighbourhoods: across faces (6), faces and edges (18), faces, edges and corners (26)."""

_KINDS = {6: 1, 18: 2, 26: 3}


def check_connectivity(connectivity: int) -> int:
    """Validate a neighbourhood size: 6, 18 or 26.

    Raises
    ------
    ValueError
        For anything else (the paper's "eight neighbouring points" are a planar grid's 3 x 3
        square; its 3-D counterpart, the 3 x 3 x 3 cube, has 26).
    """
    if isinstance(connectivity, (bool, np.bool_)) or not isinstance(connectivity,
                                                                     (int, np.integer)) \
            or int(connectivity) not in CONNECTIVITIES:
        raise ValueError(
            f'expected connectivity in {CONNECTIVITIES}, got {connectivity!r} (neighbours of a '
            f"point of the 3-D grid; the paper's eight neighbours are a planar grid's, whose "
            f'3-D counterpart is 26)')
    return int(connectivity)


def neighbours(connectivity: int) -> npt.NDArray[np.int64]:
    """Indices into `MOVES` of a neighbourhood's steps, shape (connectivity,)."""
    return np.flatnonzero(np.less_equal(STEP_KIND, _KINDS[check_connectivity(connectivity)]))


def kind_costs(step_cost: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Cost of a step along an axis, in a plane and across a cube, from costs over `MOVES` (3,).

    Raises
    ------
    ValueError
        If ``step_cost`` is not of shape (26,) or steps of one kind cost differently.
    """
    cost = np.asarray(step_cost, dtype=np.float64)
    if cost.shape != (len(MOVES),):
        raise ValueError(f'expected step_cost of shape ({len(MOVES)},), got {cost.shape}')
    costs = np.array([cost[np.equal(STEP_KIND, kind)][0] for kind in (1, 2, 3)])
    if not np.array_equal(cost, costs[STEP_KIND - 1]):
        raise ValueError('expected one cost per kind of step (along an axis, in a plane, '
                         'across a cube)')
    return costs


@numba.njit(cache=True, nogil=True)
def grid_distance(di, dj, dk, connectivity, one, two, three):
    """Cost of the cheapest obstacle-free grid path over ``(di, dj, dk)`` cells [cells].

    ``one``, ``two``, ``three``: the costs of a step along an axis, in a plane and across a
    cube (`kind_costs`), with ``two <= 2 one`` and ``three <= one + two`` (true of lengths and
    of Manhattan lengths). With ``a >= b >= c`` the sorted absolute differences:

    - 6 neighbours: ``(a + b + c) one`` (the Manhattan distance, in cells, for both costs);
    - 18: ``(b + c) two + (a - b - c) one`` if ``a >= b + c``, else, with ``s = a + b + c``,
      ``(s // 2) two + (s % 2) one`` (planar diagonals pair up the coordinates);
    - 26: ``c three + (b - c) two + (a - b) one`` (the 3-D octile distance).

    The exact distance of a graph that has every edge the search has (and more): a lower bound
    of every grid path's cost, and as a heuristic admissible and consistent.
    """
    a, b, c = abs(di), abs(dj), abs(dk)
    if a < b:
        a, b = b, a
    if b < c:
        b, c = c, b
    if a < b:
        a, b = b, a
    if connectivity == 6:
        return (a + b + c) * one
    if connectivity == 18:
        if a >= b + c:
            return (b + c) * two + (a - b - c) * one
        s = a + b + c
        return (s // 2) * two + (s % 2) * one
    return c * three + (b - c) * two + (a - b) * one


TIE_BREAK = 1e-6
"""Among open cells of (nearly) equal f the search expands the one nearest to the goal first:
the heap key is ``g + (1 + TIE_BREAK) h``, so a path costs at most ``1 + TIE_BREAK`` times the
optimum (a millionth: far below the length of a step on any grid accepted)."""


def _guards() -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """For each step, the cells it passes between (no corner cutting), as offsets (26, 6)."""
    offsets = np.zeros((len(MOVES), 6, 3), dtype=np.int64)
    counts = np.zeros(len(MOVES), dtype=np.int64)
    for m, move in enumerate(MOVES):
        axes = np.flatnonzero(move)
        for mask in itertools.product((0, 1), repeat=len(axes)):
            if 0 < sum(mask) < len(axes):
                offset = np.zeros(3, dtype=np.int64)
                offset[axes] = move[axes] * np.array(mask)
                offsets[m, counts[m]] = offset
                counts[m] += 1
    return offsets, counts


GUARD_OFFSETS, GUARD_COUNTS = _guards()
"""A diagonal step from ``c`` to ``c + d`` is allowed only if every cell ``c + m * d`` for the
partial masks ``m`` (the corners of the unit cell it crosses) is free: 2 cells for a step in a
plane, 6 for a step across a cube, none for a step along an axis."""


UNSEEN, START, CLOSED = -1, 26, 32
"""Cell states in the search: not reached, the start's "step", flag added once expanded."""


@dataclass(frozen=True)
class GridPath:
    """Result of a grid search.

    Attributes
    ----------
    cells : ndarray of int64, shape (N, 3)
        Grid indices (unpadded) from the start cell to the goal cell; empty if none was found.
    cost : float
        Cost of the path [cells] (``inf`` if none).
    expanded : int
        Cells taken from the open set and closed.
    """

    cells: npt.NDArray[np.int64]
    cost: float
    expanded: int

    @property
    def found(self) -> bool:
        """Whether a path was found."""
        return len(self.cells) > 0


@numba.njit(cache=True, nogil=True)
def _grow(keys, nodes):
    grown_keys = np.empty(2 * len(keys), dtype=keys.dtype)
    grown_nodes = np.empty(2 * len(nodes), dtype=nodes.dtype)
    grown_keys[:len(keys)] = keys
    grown_nodes[:len(nodes)] = nodes
    return grown_keys, grown_nodes


@numba.njit(cache=True, nogil=True, inline='always')
def _heap_push(keys, nodes, size, key, node):
    """Push onto the binary min-heap ``keys[:size]``; the caller ensures the capacity."""
    i = size
    while i > 0:
        parent = (i - 1) >> 1
        if keys[parent] <= key:
            break
        keys[i] = keys[parent]
        nodes[i] = nodes[parent]
        i = parent
    keys[i] = key
    nodes[i] = node


@numba.njit(cache=True, nogil=True, inline='always')
def _heap_pop(keys, nodes, size):
    """Pop the smallest key's node off ``keys[:size]`` (size > 0); the new size is size - 1."""
    top = nodes[0]
    size -= 1
    key = keys[size]
    node = nodes[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= key:
            break
        keys[i] = keys[child]
        nodes[i] = nodes[child]
        i = child
    if size > 0:
        keys[i] = key
        nodes[i] = node
    return top


@numba.njit(cache=True, nogil=True)
def _astar(free, shape, start, goal, steps, step_cost, guard_offsets, guard_counts, tie_break):
    ny, nz = shape[1], shape[2]
    count = len(steps)
    moves = np.empty(count, dtype=np.int64)
    guards = np.empty((count, 6), dtype=np.int64)
    for m in range(count):
        moves[m] = (steps[m, 0] * ny + steps[m, 1]) * nz + steps[m, 2]
        for q in range(guard_counts[m]):
            o = guard_offsets[m, q]
            guards[m, q] = (o[0] * ny + o[1]) * nz + o[2]
    n_cells = free.size
    # state: UNSEEN, or the step m (0-25, START for the start) that reached the cell, plus
    # CLOSED once expanded; g is only read where state says the cell was reached, so it needs
    # no initialisation (untouched pages of it are never even mapped)
    state = np.full(n_cells, UNSEEN, dtype=np.int8)
    g = np.empty(n_cells, dtype=np.float64)
    gi, gj, gk = goal // (ny * nz), (goal // nz) % ny, goal % nz
    weight = 1.0 + tie_break
    keys = np.empty(1 << 12, dtype=np.float64)
    nodes = np.empty(1 << 12, dtype=np.int64)
    g[start] = 0.0
    state[start] = START
    si, sj, sk = start // (ny * nz), (start // nz) % ny, start % nz
    h0 = np.sqrt(float((si - gi) ** 2 + (sj - gj) ** 2 + (sk - gk) ** 2))
    _heap_push(keys, nodes, 0, weight * h0, start)
    size = 1
    expanded = 0
    found = False
    while size > 0:
        n = _heap_pop(keys, nodes, size)
        size -= 1
        if state[n] >= CLOSED:
            continue
        state[n] += CLOSED
        expanded += 1
        if n == goal:
            found = True
            break
        gn = g[n]
        di0, dj0, dk0 = n // (ny * nz) - gi, (n // nz) % ny - gj, n % nz - gk
        for m in range(count):
            nb = n + moves[m]
            s = state[nb]
            if free[nb] == 0 or s >= CLOSED:
                continue
            ng = gn + step_cost[m]
            if s != UNSEEN and ng >= g[nb]:
                continue
            blocked = False
            for q in range(guard_counts[m]):
                if free[n + guards[m, q]] == 0:
                    blocked = True
                    break
            if blocked:
                continue
            g[nb] = ng
            state[nb] = m
            di, dj, dk = di0 + steps[m, 0], dj0 + steps[m, 1], dk0 + steps[m, 2]
            h = np.sqrt(float(di * di + dj * dj + dk * dk))
            if size == len(keys):
                keys, nodes = _grow(keys, nodes)
            _heap_push(keys, nodes, size, ng + weight * h, nb)
            size += 1
    if not found:
        return np.empty(0, dtype=np.int64), np.inf, expanded
    length = 1
    n = goal
    while n != start:
        n -= moves[state[n] - CLOSED]
        length += 1
    path = np.empty(length, dtype=np.int64)
    n = goal
    for step in range(length - 1, -1, -1):
        path[step] = n
        if step > 0:
            n -= moves[state[n] - CLOSED]
    return path, g[goal], expanded


def astar_grid(
    padded: npt.NDArray[np.uint8],
    start: npt.ArrayLike,
    goal: npt.ArrayLike,
    step_cost: npt.NDArray[np.float64] = STEP_LENGTH,
    connectivity: int = 26,
) -> GridPath:
    """A* from ``start`` to ``goal`` over the free cells of a padded grid.

    Parameters
    ----------
    padded : ndarray of uint8, shape (nx + 2, ny + 2, nz + 2), C-contiguous
        1 for free cells, 0 for blocked ones; the border must be 0.
    start, goal : array-like of int, shape (3,)
        Unpadded grid indices of free cells.
    step_cost : ndarray, shape (26,)
        Cost of each step of `MOVES` [cells], one per kind of step (`STEP_COSTS`: `STEP_LENGTH`,
        the default, or `STEP_MANHATTAN`); only the neighbourhood's steps are taken.
    connectivity : {6, 18, 26}
        The neighbourhood (`neighbours`).

    Returns
    -------
    GridPath
    """
    if padded.dtype != np.uint8 or padded.ndim != 3 or not padded.flags.c_contiguous:
        raise ValueError('expected a C-contiguous uint8 grid of 3 dimensions')
    kind_costs(step_cost)  # validates the costs
    chosen = neighbours(connectivity)
    shape = np.array(padded.shape, dtype=np.int64)
    start_flat = int(np.ravel_multi_index(np.asarray(start) + 1, padded.shape))
    goal_flat = int(np.ravel_multi_index(np.asarray(goal) + 1, padded.shape))
    cost = np.ascontiguousarray(np.asarray(step_cost, dtype=np.float64)[chosen])
    path, total, expanded = _astar(
        padded.reshape(-1), shape, start_flat, goal_flat, np.ascontiguousarray(MOVES[chosen]),
        cost, np.ascontiguousarray(GUARD_OFFSETS[chosen]),
        np.ascontiguousarray(GUARD_COUNTS[chosen]), TIE_BREAK)
    cells = np.stack(np.unravel_index(path, padded.shape), axis=-1).astype(np.int64) - 1
    return GridPath(cells.reshape(-1, 3), float(total), int(expanded))
