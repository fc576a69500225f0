"""Speed of the A* planner on the paper's scenario against three peers, measured in one run.

Target (issue 10): faster than tcod's C A* at 10, 5, 2 and 1 mm with a path no longer than
tcod's + 2 %, the free-space build reported separately (it is amortized per obstacle set), and
a plan at 1 mm in <= 5 s within 2 GB.

Every planner searches the same graph: the free grid of ``inflarm_planning.free_space`` (eq. 5
with the alert margin), 26-connected, no corner cutting, steps costing their length. Peers:

- a plain heapq A* written here (dicts and a set over flat cell indices, Euclidean heuristic);
- ``networkx.astar_path`` on a ``networkx.Graph`` of the free cells (its build reported
  separately; skipped where the graph would not fit in ``--networkx-max-gb``, ~357 bytes an
  edge measured);
- tcod's C A* (``tcod.path.CustomGraph`` + ``Pathfinder``, integer step costs 100 / 141 / 173,
  the tightest admissible heuristic tcod offers, its graph build reported separately).

inflarm and tcod are timed by the median of calls made in turn (``common.interleaved``: the
machine is shared, a busy spell then slows both alike), after a warm-up (numba's compilation is
cached on disk and measured apart in a fresh process); the slow peers by their best of 1-3
calls. Peak memory of a 1 mm build + plan is the peak RSS of a fresh process (``VmHWM`` of
``/proc/self/status``): numba's arrays are invisible to tracemalloc.

Usage: ``source scripts/env.sh && python benchmarks/bench_planning.py [--margin 0.03]
[--resolutions 10 5 2 1] [--networkx-max-gb 3]``; peers come from
``benchmarks/requirements.txt`` (a missing one is skipped with a message). ``--quick`` (of
``run_all.py``): 10 mm only, no networkx, no fresh processes.
"""

import argparse
import heapq
import itertools
import math
import os
import subprocess
import sys
import tempfile
import time

from common import Row, Target, interleaved, print_rows, skip_reason_if_missing
import numpy as np

from inflarm_planning.astar import plan
from inflarm_planning.free_space import build_free_space, clear_cache, free_space
from inflarm_planning.grid_search import GUARD_COUNTS, GUARD_OFFSETS, MOVES, STEP_LENGTH
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
from inflarm_planning.trajectory import make_trajectory

NETWORKX_BYTES_PER_EDGE = 357  # measured with tracemalloc on the 10 mm graph
TARGET_1MM_S = 5.0
TARGET_1MM_GB = 2.0
TARGET_LENGTH_RATIO = 1.02


def path_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def guard_ok(free: np.ndarray) -> list[np.ndarray]:
    """Per move, the cells from which it is allowed (destination and crossed corners free)."""
    padded = np.pad(free, 1)
    n = free.shape
    masks = []
    for m, move in enumerate(MOVES):
        def shifted(offset):
            o = np.asarray(offset) + 1
            return padded[o[0]:o[0] + n[0], o[1]:o[1] + n[1], o[2]:o[2] + n[2]]
        ok = free & shifted(move)
        for q in range(GUARD_COUNTS[m]):
            ok = ok & shifted(GUARD_OFFSETS[m, q])
        masks.append(ok)
    return masks


# --- peers -------------------------------------------------------------------------------------


def heapq_astar(free: np.ndarray, start, goal) -> np.ndarray:
    """Plain A*: heapq open set, a closed set, dicts of costs and parents, flat indices."""
    shape = free.shape
    padded = np.pad(free, 1).astype(np.uint8)
    ny, nz = padded.shape[1], padded.shape[2]
    cells = padded.reshape(-1).tobytes()
    flat = [int((int(m[0]) * ny + int(m[1])) * nz + int(m[2])) for m in MOVES]
    guards = [[int((int(o[0]) * ny + int(o[1])) * nz + int(o[2]))
               for o in GUARD_OFFSETS[m, :GUARD_COUNTS[m]]] for m in range(len(MOVES))]
    moves = list(zip(flat, STEP_LENGTH.tolist(), guards, strict=True))

    def index(c):
        return ((int(c[0]) + 1) * ny + int(c[1]) + 1) * nz + int(c[2]) + 1

    s, g = index(start), index(goal)
    gi, gj, gk = g // (ny * nz), (g // nz) % ny, g % nz

    def h(n):
        return math.sqrt((n // (ny * nz) - gi) ** 2 + ((n // nz) % ny - gj) ** 2
                         + (n % nz - gk) ** 2)

    cost, parent, closed = {s: 0.0}, {s: s}, set()
    frontier = [(h(s), s)]
    while frontier:
        _, n = heapq.heappop(frontier)
        if n in closed:
            continue
        if n == g:
            break
        closed.add(n)
        base = cost[n]
        for delta, step, guard in moves:
            nb = n + delta
            if not cells[nb] or nb in closed or not all(cells[n + q] for q in guard):
                continue
            new = base + step
            if new < cost.get(nb, math.inf):
                cost[nb] = new
                parent[nb] = n
                heapq.heappush(frontier, (new + h(nb), nb))
    else:
        raise RuntimeError('heapq A*: no path')
    path = [g]
    while path[-1] != s:
        path.append(parent[path[-1]])
    idx = np.stack(np.unravel_index(np.array(path[::-1]), padded.shape), axis=-1) - 1
    assert np.all(idx < shape)
    return idx


def networkx_graph(free: np.ndarray):
    import networkx as nx

    graph = nx.Graph()
    shape = free.shape
    graph.add_nodes_from(np.flatnonzero(free.reshape(-1)).tolist())
    for m, ok in enumerate(guard_ok(free)):
        if tuple(MOVES[m]) <= (0, 0, 0):
            continue  # undirected: each pair once (the guards are symmetric)
        src = np.argwhere(ok)
        u = np.ravel_multi_index(src.T, shape)
        v = np.ravel_multi_index((src + MOVES[m]).T, shape)
        graph.add_weighted_edges_from(zip(u.tolist(), v.tolist(),
                                          itertools.repeat(float(STEP_LENGTH[m]))))
    return graph


def networkx_astar(graph, shape, start, goal) -> np.ndarray:
    import networkx as nx

    def h(a, b):
        return math.dist(np.unravel_index(a, shape), np.unravel_index(b, shape))

    s = int(np.ravel_multi_index(start, shape))
    g = int(np.ravel_multi_index(goal, shape))
    path = nx.astar_path(graph, s, g, heuristic=h, weight='weight')
    return np.stack(np.unravel_index(np.array(path), shape), axis=-1)


AXES = (2, 0, 1)  # tcod's first axis gets its weakest heuristic term: give it our z (smallest)


def tcod_graph(free: np.ndarray):
    import tcod.path

    grid = free.transpose(AXES)
    graph = tcod.path.CustomGraph(grid.shape)
    cost = grid.astype(np.int8)
    for m, ok in enumerate(guard_ok(free)):
        move = tuple(int(v) for v in MOVES[m][list(AXES)])
        step = int(round(100 * STEP_LENGTH[m]))
        condition = None if GUARD_COUNTS[m] == 0 else ok.transpose(AXES).astype(np.int8)
        graph.add_edge(move, step, cost=cost, condition=condition)
    # octile on tcod's last two axes (ours x, y) + z * |dz|: consistent for z <= 173 - 141
    graph.set_heuristic(cardinal=100, diagonal=141, z=32)
    return graph


def tcod_astar(graph, start, goal) -> np.ndarray:
    import tcod.path

    finder = tcod.path.Pathfinder(graph)
    finder.add_root(tuple(int(v) for v in np.asarray(start)[list(AXES)]))
    path = finder.path_to(tuple(int(v) for v in np.asarray(goal)[list(AXES)]))
    return path[:, np.argsort(AXES)]


# --- fresh-process figures ---------------------------------------------------------------------

CHILD_1MM = """
import re, time
from inflarm_planning.astar import plan
from inflarm_planning.scenario import GOAL, OBSTACLE, START
from inflarm_planning.free_space import free_space
def kib():  # peak RSS of this process image (ru_maxrss would include the forking parent's)
    with open('/proc/self/status') as status:
        return int(re.search(r'VmHWM:\\s+(\\d+) kB', status.read()).group(1))
base = kib()
plan(START, GOAL, [OBSTACLE], 0.01, {margin})  # compile or load the kernel
space = free_space([OBSTACLE], 0.001, {margin})
built = kib()
t0 = time.perf_counter()
result = plan(START, GOAL, [OBSTACLE], 0.001, {margin})
elapsed = time.perf_counter() - t0
print(base, built, kib(), elapsed, space.build_time_s, result.expanded)
"""

CHILD_COMPILE = """
import time
t0 = time.perf_counter()
from inflarm_planning.astar import plan
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START
t1 = time.perf_counter()
plan(START, GOAL, [OBSTACLE], 0.01, ALERT_MARGIN)
print(t1 - t0, time.perf_counter() - t1)
"""


def fresh_process(code: str, env: dict | None = None) -> list[float]:
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, env=dict(os.environ, **(env or {})), timeout=600)
    return [float(v) for v in out.stdout.split()]


def bench_resolution(res_mm: float, margin: float, peers: dict, networkx_max_gb: float,
                     rounds: int, quick: bool) -> dict:
    """Figures at one resolution: build, inflarm (both costs), tcod, trajectory, heapq, networkx
    (times [s], lengths [m]); a peer's entry is absent where it was not run (networkx is not
    run with ``quick``)."""
    r = res_mm * 1e-3
    clear_cache()
    build = interleaved({'build': lambda: build_free_space([OBSTACLE], r, margin)},
                        1 if res_mm < 2 else 3, number=1)['build']
    space = free_space([OBSTACLE], r, margin)  # into the cache: plan() reuses it
    result = plan(START, GOAL, [OBSTACLE], r, margin)  # the path, and a warm-up
    paper = plan(START, GOAL, [OBSTACLE], r, margin, cost='paper')
    start, goal = result.cells[0], result.cells[-1]
    free = space.free.copy()
    lattice = space.lattice
    contenders = {
        'ours': lambda: plan(START, GOAL, [OBSTACLE], r, margin),
        'paper': lambda: plan(START, GOAL, [OBSTACLE], r, margin, cost='paper'),
    }
    row = {'mm': res_mm, 'shape': lattice.shape, 'cells': lattice.size, 'build': build.median_s,
           'rounds': rounds, 'ours_len': path_length(lattice.points(result.cells)),
           'expanded': result.expanded, 'searches': result.searches,
           'paper_len': path_length(lattice.points(paper.cells))}
    if peers['tcod'] is None:
        t0 = time.perf_counter()
        graph = tcod_graph(free)
        row['tcod_build'] = time.perf_counter() - t0
        row['tcod_len'] = path_length(lattice.points(tcod_astar(graph, start, goal)))
        contenders['tcod'] = lambda: tcod_astar(graph, start, goal)
    timing = interleaved(contenders, rounds, number=1)
    contenders.clear()  # frees tcod's graph
    for name, t in timing.items():
        row[name], row[f'{name}_best'] = t.median_s, t.best_s

    trajectory = make_trajectory(result.path, [OBSTACLE], margin)
    row['trajectory'] = interleaved(
        {'t': lambda: make_trajectory(result.path, [OBSTACLE], margin)}, 3, number=1)['t'].best_s
    row['trajectory_len'], row['waypoints'] = trajectory.length, len(trajectory.points)

    slow = {}  # the slow peers' results, from their timed calls

    def heap():
        slow['heapq'] = heapq_astar(free, start, goal)

    row['heapq'] = interleaved({'heapq': heap}, 3 if res_mm >= 5 else 1, number=1)['heapq'].best_s
    row['heapq_len'] = path_length(lattice.points(slow['heapq']))

    if peers['networkx'] is None and quick:
        row['networkx_skipped'] = 'not in --quick (its graph build takes seconds)'
    elif peers['networkx'] is None:
        edges = int(sum(ok.sum() for ok in guard_ok(free)) // 2)
        need_gb = edges * NETWORKX_BYTES_PER_EDGE / 1e9
        if need_gb > networkx_max_gb:
            row['networkx_skipped'] = (f'its graph of {edges / 1e6:.0f} M edges would need '
                                       f'~{need_gb:.0f} GB (over --networkx-max-gb)')
        else:
            t0 = time.perf_counter()
            nx_graph = networkx_graph(free)
            row['networkx_build'] = time.perf_counter() - t0

            def nx_plan():
                slow['networkx'] = networkx_astar(nx_graph, free.shape, start, goal)

            row['networkx'] = interleaved({'nx': nx_plan}, 3, number=1)['nx'].best_s
            row['networkx_len'] = path_length(lattice.points(slow['networkx']))
            del nx_graph
    return row


def measure(margin: float, resolutions: list[float], networkx_max_gb: float, quick: bool
            ) -> dict:
    """Every figure of the benchmark (--quick: no fresh processes, fewer rounds)."""
    compile_s = None
    if not quick:
        with tempfile.TemporaryDirectory() as cache:
            imports, first = fresh_process(CHILD_COMPILE, {'NUMBA_CACHE_DIR': cache})
            _, cached = fresh_process(CHILD_COMPILE, {'NUMBA_CACHE_DIR': cache})
        compile_s = {'imports': imports, 'first': first, 'cached': cached}
    peers = {name: skip_reason_if_missing(name) for name in ('networkx', 'tcod')}
    rounds = {10: 10} if quick else {10: 100, 5: 30, 2: 6}
    resolution_rows = [bench_resolution(mm, margin, peers, networkx_max_gb,
                                        rounds.get(int(mm), 2), quick) for mm in resolutions]
    fresh = None
    if not quick:
        base, built, peak, elapsed, build_s, expanded = fresh_process(
            CHILD_1MM.format(margin=margin))
        fresh = {'base_gib': base / 2**20, 'built_gib': built / 2**20, 'peak_gib': peak / 2**20,
                 'plan_s': elapsed, 'build_s': build_s, 'expanded': int(expanded)}
    return {'margin': margin, 'compile': compile_s, 'peers': peers,
            'resolutions': resolution_rows, 'fresh_1mm': fresh}


def rows(m: dict) -> list[Row]:
    """Per resolution: inflarm against tcod (time and length targets), heapq and networkx;
    the 1 mm plan in a fresh process; the kernel from numba's disk cache."""
    out = []
    peers = m['peers']
    for r in m['resolutions']:
        mm = f"{r['mm']:g} mm"
        grid = f"grid {'x'.join(map(str, r['shape']))}, {r['expanded']} cells expanded"
        if peers['tcod'] is None:
            out += [Row(f'A* at {mm}', r['ours'] * 1e3, 'ms', "tcod's C A*", r['tcod'] * 1e3,
                        Target(ratio_at_most=1.0),
                        f"{grid}; median of {r['rounds']} interleaved calls; free-space build "
                        f"{r['build'] * 1e3:.0f} ms apart"),
                    Row(f'path length at {mm}', r['ours_len'] * 1e3, 'mm', "tcod's path",
                        r['tcod_len'] * 1e3, Target(ratio_at_most=TARGET_LENGTH_RATIO))]
        else:
            out.append(Row.skipped(f'A* at {mm} against tcod', peers['tcod']))
        out.append(Row(f'A* at {mm}', r['ours'] * 1e3, 'ms', 'plain heapq A*', r['heapq'] * 1e3,
                       note='' if peers['tcod'] is None else grid))
        if peers['networkx'] is not None:
            out.append(Row.skipped(f'A* at {mm} against networkx', peers['networkx']))
        elif 'networkx_skipped' in r:
            out.append(Row.skipped(f'A* at {mm} against networkx', r['networkx_skipped']))
        else:
            out.append(Row(f'A* at {mm}', r['ours'] * 1e3, 'ms', 'networkx.astar_path',
                           r['networkx'] * 1e3,
                           note=f"its graph build {r['networkx_build']:.1f} s apart"))
    fresh = m['fresh_1mm']
    if fresh is not None:
        out += [Row('plan at 1 mm, fresh process', fresh['plan_s'], 's',
                    target=Target(at_most=TARGET_1MM_S),
                    note=f"free-space build {fresh['build_s']:.2f} s apart"),
                Row('peak RSS, 1 mm build + plan', fresh['peak_gib'], 'GiB',
                    'after the imports', fresh['base_gib'], Target(at_most=TARGET_1MM_GB))]
    c = m['compile']
    if c is not None:
        out.append(Row('A* kernel, first call from the disk cache', c['cached'], 's',
                       'first call, compiling', c['first'], note='numba, fresh processes'))
    return out


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: 10 mm only, 10 rounds, no networkx, no fresh
    processes; full: 10, 5, 2 and 1 mm, about 2 min)."""
    resolutions = [10.0] if quick else [10.0, 5.0, 2.0, 1.0]
    return rows(measure(ALERT_MARGIN, resolutions, 3.0, quick))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--margin', type=float, default=ALERT_MARGIN,
                        help=f'alert margin [m] (default {ALERT_MARGIN}, the node default)')
    parser.add_argument('--resolutions', type=float, nargs='+', default=[10, 5, 2, 1],
                        help='grid resolutions [mm]')
    parser.add_argument('--networkx-max-gb', type=float, default=3.0,
                        help='skip networkx where its graph would need more [GB]')
    args = parser.parse_args(argv)
    m = measure(args.margin, args.resolutions, args.networkx_max_gb, quick=False)
    print(f"paper's scenario: start {START} m, goal {GOAL} m, obstacle "
          f'{OBSTACLE.min_corner}-{OBSTACLE.max_corner} m, alert margin {args.margin} m\n')
    c = m['compile']
    print(f"numba kernel: first call {c['first']:.2f} s compiling, {c['cached'] * 1e3:.0f} ms "
          f"from the disk cache (imports {c['imports']:.2f} s)\n")
    for name, reason in m['peers'].items():
        if reason is not None:
            print(f'  ({name} skipped: {reason})')
    for r in m['resolutions']:
        print(f"{r['mm']:g} mm: grid {r['shape']} ({r['cells'] / 1e6:.2f} M points), "
              f"free-space build {r['build'] * 1e3:.1f} ms; median of {r['rounds']} "
              f'interleaved calls (smallest in brackets)')
        print(f"  inflarm A*        {r['ours'] * 1e3:9.2f} ms ({r['ours_best'] * 1e3:.2f})  "
              f"length {r['ours_len'] * 1e3:.2f} mm  ({r['expanded']} cells expanded, "
              f"{r['searches']} crop(s))")
        print(f"  inflarm eq. 7     {r['paper'] * 1e3:9.2f} ms ({r['paper_best'] * 1e3:.2f})  "
              f"length {r['paper_len'] * 1e3:.2f} mm")
        if 'tcod' in r:
            print(f"  tcod A*           {r['tcod'] * 1e3:9.2f} ms ({r['tcod_best'] * 1e3:.2f})  "
                  f"length {r['tcod_len'] * 1e3:.2f} mm   inflarm is "
                  f"{r['tcod'] / r['ours']:.1f}x faster, length ratio "
                  f"{r['ours_len'] / r['tcod_len']:.4f} (graph build "
                  f"{r['tcod_build'] * 1e3:.0f} ms)")
        print(f"  trajectory        {r['trajectory'] * 1e3:9.2f} ms  length "
              f"{r['trajectory_len'] * 1e3:.2f} mm (shortcut, smoothed, {r['waypoints']} "
              f'waypoints)')
        print(f"  heapq A*          {r['heapq'] * 1e3:9.2f} ms  length "
              f"{r['heapq_len'] * 1e3:.2f} mm   inflarm is {r['heapq'] / r['ours']:.1f}x faster")
        if 'networkx_skipped' in r:
            print(f"  networkx          skipped: {r['networkx_skipped']}")
        elif 'networkx' in r:
            print(f"  networkx          {r['networkx'] * 1e3:9.2f} ms  length "
                  f"{r['networkx_len'] * 1e3:.2f} mm   inflarm is "
                  f"{r['networkx'] / r['ours']:.1f}x faster (graph build "
                  f"{r['networkx_build']:.1f} s)")
        print()
    f = m['fresh_1mm']
    print(f"1 mm in a fresh process: build {f['build_s']:.2f} s, plan {f['plan_s']:.2f} s "
          f"({f['expanded']} cells expanded); peak RSS {f['base_gib']:.2f} GiB after imports, "
          f"{f['built_gib']:.2f} GiB after the build, {f['peak_gib']:.2f} GiB after the plan")
    print()
    print_rows('planning', rows(m))
    return 0


if __name__ == '__main__':
    sys.exit(main())
