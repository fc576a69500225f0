"""26-connected A* over a padded free grid, compiled with numba (the search kernel of `astar`).

The grid is a flat ``uint8`` array in C order of shape ``(nx + 2, ny + 2, nz + 2)`` whose
border cells are blocked (0), so a step never leaves the array. Costs are in cells; the caller
scales them by the resolution.

The kernel is plain A* with an open set (a binary heap with lazy deletion) and a closed set:
``f = g + h`` with ``g`` the cost of the path so far (the sum of the step costs it is given)
and ``h`` the Euclidean distance to the goal. It releases the GIL (``nogil``), so a node can run
it in a worker thread while its executor keeps spinning, and numba caches the compiled code on
disk (``cache=True``): only the first call on a machine pays the ~1-2 s compilation.
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
def _astar(free, shape, start, goal, step_cost, guard_offsets, guard_counts, tie_break):
    ny, nz = shape[1], shape[2]
    moves = np.empty(26, dtype=np.int64)
    steps = np.empty((26, 3), dtype=np.int64)
    guards = np.empty((26, 6), dtype=np.int64)
    m = 0
    for di in range(-1, 2):
        for dj in range(-1, 2):
            for dk in range(-1, 2):
                if di != 0 or dj != 0 or dk != 0:
                    moves[m] = (di * ny + dj) * nz + dk
                    steps[m, 0], steps[m, 1], steps[m, 2] = di, dj, dk
                    m += 1
    for m in range(26):
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
        for m in range(26):
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
) -> GridPath:
    """A* from ``start`` to ``goal`` over the free cells of a padded grid.

    Parameters
    ----------
    padded : ndarray of uint8, shape (nx + 2, ny + 2, nz + 2), C-contiguous
        1 for free cells, 0 for blocked ones; the border must be 0.
    start, goal : array-like of int, shape (3,)
        Unpadded grid indices of free cells.
    step_cost : ndarray, shape (26,)
        Cost of each step of `MOVES` [cells]: `STEP_LENGTH` (path length, the default) or
        `STEP_MANHATTAN` (Manhattan length). The Euclidean heuristic must not exceed it.

    Returns
    -------
    GridPath
    """
    if padded.dtype != np.uint8 or padded.ndim != 3 or not padded.flags.c_contiguous:
        raise ValueError('expected a C-contiguous uint8 grid of 3 dimensions')
    shape = np.array(padded.shape, dtype=np.int64)
    start_flat = int(np.ravel_multi_index(np.asarray(start) + 1, padded.shape))
    goal_flat = int(np.ravel_multi_index(np.asarray(goal) + 1, padded.shape))
    cost = np.ascontiguousarray(step_cost, dtype=np.float64)
    if cost.shape != (26,):
        raise ValueError(f'expected step_cost of shape (26,), got {cost.shape}')
    path, total, expanded = _astar(padded.reshape(-1), shape, start_flat, goal_flat, cost,
                                   GUARD_OFFSETS, GUARD_COUNTS, TIE_BREAK)
    cells = np.stack(np.unravel_index(path, padded.shape), axis=-1).astype(np.int64) - 1
    return GridPath(cells.reshape(-1, 3), float(total), int(expanded))
