"""An independent check of planned paths, for the planning tests: dense sampling, no planner code.

The arm is drawn from eq. (6) of 001_... as the paper states it, ``(z - l1)^2 + x^2 + y^2 =
l1^2``, solved here again: PEA1 from the mount (0, 0, 0) to (0, 0, l1), PEA2 from there to the
end. Shortest grid paths come from scipy's Dijkstra over a graph built here from a free grid and
a neighbourhood. Nothing of ``inflarm_planning`` is used.
"""

import itertools

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

TOLERANCE = 1e-9
"""[m] A point on a box's surface is outside it: the alert region's border belongs to the free
space up to rounding (grid points of the paper's millimetres lie exactly on it)."""


def grow(low, high, margin):
    return np.asarray(low, float) - margin, np.asarray(high, float) + margin


def strictly_inside(points, low, high):
    """Points inside the box by more than TOLERANCE on every axis, shape (...)."""
    p = np.asarray(points, float)
    return np.all((p > np.asarray(low) + TOLERANCE) & (p < np.asarray(high) - TOLERANCE), axis=-1)


def densify(path, spacing):
    """Points along a polyline no farther apart than ``spacing``, vertices included."""
    path = np.asarray(path, float)
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / spacing)), 1)
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.vstack(out)


def axis_points(ends, samples=400):
    """Points on PEA1 and PEA2 for each end point, shape (N, 2 * samples, 3)."""
    ends = np.asarray(ends, float).reshape(-1, 3)
    x, y, z = ends.T
    l1 = (x * x + y * y + z * z) / (2.0 * z)
    joint = np.stack([np.zeros_like(l1), np.zeros_like(l1), l1], axis=-1)
    t = np.linspace(0.0, 1.0, samples)[None, :, None]
    pea1 = t * joint[:, None, :]
    pea2 = joint[:, None, :] + t * (ends - joint)[:, None, :]
    return np.concatenate([pea1, pea2], axis=1)


def violations(path, obstacles, margin, spacing=0.0005, samples=400):
    """What is wrong with a path, as strings (empty if nothing).

    Parameters
    ----------
    path : (N, 3) end points [m]
    obstacles : list of (low, high) corner pairs [m]
    margin : alert margin [m]
    """
    ends = densify(path, spacing)
    problems = []
    for k, (low, high) in enumerate(obstacles):
        a_low, a_high = grow(low, high, margin)
        inside = strictly_inside(ends, a_low, a_high)
        if inside.any():
            problems.append(f'end in the alert region of box {k} at {ends[inside][0].tolist()}')
        for first in range(0, len(ends), 200):
            part = ends[first:first + 200]
            hit = strictly_inside(axis_points(part, samples), low, high).any(axis=1)
            if hit.any():
                problems.append(f'an axis crosses box {k} with the end at {part[hit][0].tolist()}')
                break
    return problems


def axes_clear_of_alert_regions(points, obstacles, margin, samples=2000, clearance=0.0):
    """Whether, at each end point, no sample of either axis lies inside an alert region grown by
    ``clearance`` more, shape (N,).

    With ``clearance = 0`` an axis merely touching a region is clear; with a clearance of at
    least half the sample spacing, every axis reported clear truly is (it is farther than that
    from the region at every sample, so it cannot reach it in between).
    """
    pts = axis_points(points, samples)
    clear = np.ones(len(pts), dtype=bool)
    for low, high in obstacles:
        a_low, a_high = grow(low, high, margin + clearance)
        clear &= ~strictly_inside(pts, a_low, a_high).any(axis=1)
    return clear


def neighbourhood(connectivity):
    """The steps to a cell's neighbours, (connectivity, 3): across faces (6), faces and edges
    (18), or the whole 3 x 3 x 3 cube (26)."""
    changed = {6: 1, 18: 2, 26: 3}[connectivity]  # coordinates a step may change
    return np.array([m for m in itertools.product((-1, 0, 1), repeat=3)
                     if 0 < np.count_nonzero(m) <= changed])


def grid_graph(free, connectivity, cost='length'):
    """The free grid as a sparse graph: an edge for each step of the neighbourhood between free
    cells that cuts no corner (every cell of the unit cell it crosses is free), weighted by the
    step's length (``'length'``) or its Manhattan length (``'manhattan'``)."""
    shape = np.array(free.shape)
    cells = np.argwhere(free)
    rows, cols, weights = [], [], []
    for move in neighbourhood(connectivity):
        ok = np.ones(len(cells), dtype=bool)
        for mask in itertools.product((0, 1), repeat=3):
            corner = cells + move * np.array(mask)
            inside = np.all((corner >= 0) & (corner < shape), axis=1)
            ok &= inside
            ok[inside] &= free[tuple(corner[inside].T)]
        rows.append(np.ravel_multi_index(cells[ok].T, free.shape))
        cols.append(np.ravel_multi_index((cells[ok] + move).T, free.shape))
        weight = np.linalg.norm(move) if cost == 'length' else float(np.abs(move).sum())
        weights.append(np.full(ok.sum(), weight))
    return coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(free.size, free.size)).tocsr()


def shortest_costs(free, first, connectivity, cost='length'):
    """Dijkstra's cost [cells] from cell ``first`` to every cell, shaped as ``free``."""
    graph = grid_graph(free, connectivity, cost)
    distance = dijkstra(graph, indices=np.ravel_multi_index(tuple(first), free.shape))
    return distance.reshape(free.shape)
