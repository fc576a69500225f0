"""Speed of the experiential knowledge database (section 3.2 of 001_...).

Prints, for the paper's full 67,200-point grid (32 MB of .npy arrays in a temporary directory):

- lookup time per call [us] of ``KnowledgeDatabase.lookup`` (target <= 10 us) against two
  baselines measured in the same run: a nearest search with ``np.argmin`` over the points
  array, and a plain dict keyed by the whole-centimetre coordinates (rounding + dict + decode,
  the cheapest Python alternative);
- open time [ms] of the full database (target: the worst of 20 opens <= 50 ms), against
  ``np.fromfile`` reading its codes all;
- with ``--full-build``: wall time of ``build_knowledge_database`` over all 67,200 points
  (target <= 120 s on the 2-core machine);
- in the full run (and with ``--distributed``): build speed [points/s] on a Dask cluster of 1 and
  of 2 workers (``distributed.LocalCluster``, one process and one thread per worker, on this
  machine) over 6,400 points (40 x 40 x 4) x 30 trials, against the local build in this process
  and on the local pool of 2 processes; the files are checked byte-identical first.

Passes over the same targets are timed round-robin (``common.interleaved``).

Run: ``source scripts/env.sh && python benchmarks/bench_knowledge.py [--full-build]
[--batch-size N] [--workers N] [--distributed]``
"""

import argparse
import os
from pathlib import Path
import sys
import tempfile
import time

from common import Row, Target, interleaved, print_rows
import numpy as np

from inflarm_bringup.knowledge_cli import knowledge_plant
from inflarm_control.knowledge import (
    DEFAULT_GRID,
    KnowledgeDatabase,
    KnowledgeGrid,
    build_knowledge_database,
    nearest_knowledge_point,
)

OPEN_TARGET_MS = 50.0
BUILD_TARGET_S = 120.0


def bench_lookup_and_open(tmp: Path, n_targets: int, n_argmin: int, rounds: int,
                          opens: int) -> dict:
    """Per call [us] of the lookups and their baselines; open and read-all times [ms]."""
    rng = np.random.default_rng(7)
    path = tmp / 'knowledge'
    with KnowledgeDatabase.create(path) as db:
        for start in range(0, DEFAULT_GRID.size, 8192):
            idx = np.arange(start, min(start + 8192, DEFAULT_GRID.size))
            db.write(idx, rng.uniform(0.0, 40e3, size=(len(idx), 50, 5)))
    size_mb = sum(f.stat().st_size for f in path.iterdir()) / 1e6

    opening = interleaved({'open': lambda: KnowledgeDatabase.open(path).close(),
                           'read all': lambda: np.fromfile(path / 'codes.npy', dtype=np.uint8)},
                          opens, number=1)

    db = KnowledgeDatabase.open(path)
    lower, upper = np.array(DEFAULT_GRID.lower), np.array(DEFAULT_GRID.upper)
    targets = [tuple(p) for p in rng.uniform(lower, upper - 1e-6, size=(n_targets, 3)).tolist()]
    arrays = [np.array(t) for t in targets]

    points = DEFAULT_GRID.points()
    codes = db._data  # the same uint16 rows the database decodes

    def argmin_lookup(t):
        i = int(np.argmin(np.sum((points - t) ** 2, axis=1)))
        return points[i], codes[i] * db.scale

    table = {tuple(np.rint(p * 100).astype(int).tolist()): i for i, p in enumerate(points)}

    def dict_lookup(t):
        i = table[(round(t[0] * 100), round(t[1] * 100), round(t[2] * 100))]
        return points[i], codes[i] * db.scale

    # Same answers before timing anything.
    for t in targets[:200]:
        p, m = db.lookup(t)
        q, n = argmin_lookup(t)
        np.testing.assert_allclose(p, q, atol=1e-12)
        np.testing.assert_allclose(m, n)

    def passes(fn, over):
        def one_pass():
            for t in over:
                fn(t)
        return one_pass

    lists = {'lookup': targets, 'lookup ndarray': arrays, 'nearest': targets,
             'argmin': targets[:n_argmin], 'dict': targets}
    fns = {'lookup': db.lookup, 'lookup ndarray': db.lookup, 'nearest': nearest_knowledge_point,
           'argmin': argmin_lookup, 'dict': dict_lookup}
    timing = interleaved({name: passes(fns[name], lists[name]) for name in lists}, rounds,
                         number=1)
    db.close()
    return {'size_mb': size_mb, 'targets': n_targets, 'opens': opens,
            'open_median_ms': opening['open'].median_ms,
            'open_worst_ms': opening['open'].worst_s * 1e3,
            'read_all_ms': opening['read all'].median_ms,
            **{name: timing[name].median_us / len(lists[name]) for name in lists}}


def bench_full_build(tmp: Path, batch_size: int | None, workers: int, progress: bool) -> dict:
    """Wall time [s] of the full build."""
    path = tmp / 'built'
    kwargs = {} if batch_size is None else {'batch_size': batch_size}
    t0 = time.perf_counter()
    db = build_knowledge_database(path, plant_factory=knowledge_plant, progress=progress,
                                  workers=workers, **kwargs)
    wall = time.perf_counter() - t0
    filled = db.n_filled
    db.close()
    return {'wall_s': wall, 'filled': filled, 'batch_size': batch_size, 'workers': workers}


# 6,400 points of the default grid (its 4 lowest z values), in blocks of 800: 8 blocks, so two
# workers share them evenly.
SCALING_GRID = KnowledgeGrid(DEFAULT_GRID.origin, DEFAULT_GRID.spacing, (40, 40, 4))
SCALING_BLOCK = 800


def _bytes(path: Path) -> bytes:
    return b''.join((path / name).read_bytes() for name in sorted(p.name for p in path.iterdir()))


def bench_distributed_build(tmp: Path) -> dict:
    """Build speed [points/s] in this process, on the local pool of 2 and on Dask clusters of 1
    and 2 workers, over `SCALING_GRID`, and the machine's load (1-min load average, the larger
    of before and after); raises if a database differs from the local build's."""
    from distributed import Client, LocalCluster

    def build(name: str, **where) -> float:
        path = tmp / name
        t0 = time.perf_counter()
        build_knowledge_database(path, SCALING_GRID, plant_factory=knowledge_plant,
                                 batch_size=SCALING_BLOCK, progress=False, **where).close()
        speed = SCALING_GRID.size / (time.perf_counter() - t0)
        if _bytes(path) != _bytes(tmp / 'here'):
            raise AssertionError(f'the {name} build differs from the local one')
        return speed

    load = os.getloadavg()[0]
    speeds = {'here': build('here', workers=1), 'pool 2': build('pool 2', workers=2)}
    for n in (1, 2):
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            client.wait_for_workers(n)
            client.run(knowledge_plant, 1)  # imports done before the clock starts
            speeds[f'dask {n}'] = build(f'dask {n}', scheduler=cluster.scheduler_address)
    return {**speeds, 'load': max(load, os.getloadavg()[0])}


def rows(lookup: dict, build: dict | None, scaling: dict | None = None) -> list[Row]:
    """The summary rows."""
    grid = f"full grid, {DEFAULT_GRID.size} points, {lookup['size_mb']:.1f} MB"
    out = [
        Row('KnowledgeDatabase.lookup (tuple)', lookup['lookup'], 'us',
            'dict keyed by whole centimetres', lookup['dict'], note=grid),
        Row('KnowledgeDatabase.lookup (tuple)', lookup['lookup'], 'us',
            'np.argmin nearest search', lookup['argmin']),
        Row(f"KnowledgeDatabase.open, worst of {lookup['opens']}", lookup['open_worst_ms'], 'ms',
            'np.fromfile of the whole codes.npy', lookup['read_all_ms'],
            Target(at_most=OPEN_TARGET_MS), f"median {lookup['open_median_ms']:.3f} ms"),
    ]
    if build is not None:
        out.append(Row(f"build_knowledge_database, {build['filled']} points", build['wall_s'],
                       's', target=Target(at_most=BUILD_TARGET_S),
                       note=f"30 trials x 20 s each, {build['workers']} worker(s)"))
    if scaling is not None:
        note = (f'{SCALING_GRID.size} points x 30 trials, blocks of {SCALING_BLOCK}, workers on'
                f" this 2-core machine at load {scaling['load']:.1f}; files byte-identical")
        out += [
            Row('knowledge build on Dask, 1 worker', scaling['dask 1'], 'pt/s',
                'local build in one process', scaling['here'], note=note),
            Row('knowledge build on Dask, 2 workers', scaling['dask 2'], 'pt/s',
                'local pool of 2 processes', scaling['pool 2'], note=note),
            Row('knowledge build on Dask, 2 workers', scaling['dask 2'], 'pt/s',
                'Dask, 1 worker', scaling['dask 1'], note=note),
        ]
    return out


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: fewer targets and rounds, no build; full: with the
    full build and the Dask scaling, about 3 min)."""
    with tempfile.TemporaryDirectory() as tmp:
        if quick:
            return rows(bench_lookup_and_open(Path(tmp), 300, 30, 3, 5), None)
        lookup = bench_lookup_and_open(Path(tmp), 2000, 300, 5, 20)
        return rows(lookup, bench_full_build(Path(tmp), None, 2, progress=False),
                    bench_distributed_build(Path(tmp)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--full-build', action='store_true', help='time the 67,200-point build')
    parser.add_argument('--batch-size', type=int, default=None, help='arms simulated at once')
    parser.add_argument('--workers', type=int, default=2, help='build processes (2 cores)')
    parser.add_argument('--distributed', action='store_true',
                        help='build speed on Dask clusters of 1 and 2 workers (about 1 min)')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        m = bench_lookup_and_open(Path(tmp), 2000, 300, 5, 20)
        build = (bench_full_build(Path(tmp), args.batch_size, args.workers, progress=True)
                 if args.full_build else None)
        scaling = bench_distributed_build(Path(tmp)) if args.distributed else None
    print(f"full grid: {DEFAULT_GRID.size} points, file {m['size_mb']:.2f} MB")
    print(f"lookup (tuple)       {m['lookup']:8.2f} us")
    print(f"lookup (ndarray)     {m['lookup ndarray']:8.2f} us")
    print(f"nearest_knowledge_point {m['nearest']:5.2f} us")
    print(f"baseline np.argmin   {m['argmin']:8.2f} us   lookup is "
          f"{m['argmin'] / m['lookup']:7.1f}x faster")
    print(f"baseline dict        {m['dict']:8.2f} us   lookup is "
          f"{m['dict'] / m['lookup']:7.2f}x faster")
    print(f"open (median of {m['opens']})  {m['open_median_ms']:8.3f} ms   max "
          f"{m['open_worst_ms']:.3f} ms   target <= {OPEN_TARGET_MS:.0f} ms")
    print(f"baseline read all    {m['read_all_ms']:8.3f} ms   open is "
          f"{m['read_all_ms'] / m['open_median_ms']:7.1f}x faster")
    if build is not None:
        print(f"full build           {build['wall_s']:8.1f} s    {build['filled']} points x 30 "
              f"trials x 20 s, batch {build['batch_size'] or 'default'}, {build['workers']} "
              f"worker(s)   target <= {BUILD_TARGET_S:.0f} s")
    if scaling is not None:
        for name, speed in scaling.items():
            if name == 'load':
                continue
            print(f'build {name:14s} {speed:8.1f} points/s   {SCALING_GRID.size} points x 30'
                  ' trials')
    print()
    print_rows('knowledge', rows(m, build, scaling))
    return 0


if __name__ == '__main__':
    sys.exit(main())
