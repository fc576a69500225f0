"""Speed of the experiential knowledge database (section 3.2 of 001_...).

Prints, for the paper's full 67,200-point grid (a 32 MB file in a temporary directory):

- lookup time per call [us] of ``KnowledgeDatabase.lookup`` against two baselines measured in the
  same run: a nearest search with ``np.argmin`` over the points array, and a plain dict keyed by
  the whole-centimetre coordinates (rounding + dict + decode, the cheapest Python alternative);
- open time [ms] of the full file (target <= 50 ms), against ``np.fromfile`` reading it all;
- with ``--full-build``: wall time of ``build_knowledge_database`` over all 67,200 points
  (target <= 120 s on the 2-core machine).

Run: ``PYTHONPATH=inflarm_model:inflarm_control:inflarm_hw .venv/bin/python
benchmarks/bench_knowledge.py [--full-build] [--batch-size N] [--workers N]``
"""

import argparse
from pathlib import Path
import statistics
import tempfile
import time
import timeit

import numpy as np

from inflarm_bringup.knowledge_cli import knowledge_plant
from inflarm_control.knowledge import (
    DEFAULT_GRID,
    KnowledgeDatabase,
    build_knowledge_database,
    nearest_knowledge_point,
)

LOOKUP_TARGET_US = 10.0
OPEN_TARGET_MS = 50.0
BUILD_TARGET_S = 120.0


def per_call_us(fn, targets, repeat=5):
    """Best of ``repeat`` passes over ``targets``, per call [us]."""

    def one_pass():
        for t in targets:
            fn(t)

    return min(timeit.repeat(one_pass, number=1, repeat=repeat)) / len(targets) * 1e6


def bench_lookup_and_open(tmp: Path) -> None:
    rng = np.random.default_rng(7)
    path = tmp / 'knowledge.db'
    with KnowledgeDatabase.create(path) as db:
        for start in range(0, DEFAULT_GRID.size, 8192):
            idx = np.arange(start, min(start + 8192, DEFAULT_GRID.size))
            db.write(idx, rng.uniform(0.0, 40e3, size=(len(idx), 50, 5)))
    size_mb = path.stat().st_size / 1e6

    opens = []
    for _ in range(20):
        t0 = time.perf_counter()
        db = KnowledgeDatabase.open(path)
        opens.append((time.perf_counter() - t0) * 1e3)
        db.close()
    t0 = time.perf_counter()
    np.fromfile(path, dtype=np.uint8)
    read_all_ms = (time.perf_counter() - t0) * 1e3

    db = KnowledgeDatabase.open(path)
    lower, upper = np.array(DEFAULT_GRID.lower), np.array(DEFAULT_GRID.upper)
    targets = [tuple(p) for p in rng.uniform(lower, upper - 1e-6, size=(2000, 3)).tolist()]

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

    ours = per_call_us(db.lookup, targets)
    ours_array = per_call_us(db.lookup, [np.array(t) for t in targets])
    snap = per_call_us(nearest_knowledge_point, targets)
    argmin = per_call_us(argmin_lookup, targets[:300], repeat=3)
    dict_us = per_call_us(dict_lookup, targets)

    print(f'full grid: {DEFAULT_GRID.size} points, file {size_mb:.2f} MB')
    print(
        f'lookup (tuple)       {ours:8.2f} us   target <= {LOOKUP_TARGET_US:.0f} us'
        f'  {"OK" if ours <= LOOKUP_TARGET_US else "SLOW"}'
    )
    print(f'lookup (ndarray)     {ours_array:8.2f} us')
    print(f'nearest_knowledge_point {snap:5.2f} us')
    print(f'baseline np.argmin   {argmin:8.2f} us   lookup is {argmin / ours:7.1f}x faster')
    print(f'baseline dict        {dict_us:8.2f} us   lookup is {dict_us / ours:7.2f}x faster')
    med = statistics.median(opens)
    print(
        f'open (median of 20)  {med:8.3f} ms   max {max(opens):.3f} ms'
        f'   target <= {OPEN_TARGET_MS:.0f} ms  {"OK" if max(opens) <= OPEN_TARGET_MS else "SLOW"}'
    )
    print(f'baseline read all    {read_all_ms:8.3f} ms   open is {read_all_ms / med:7.1f}x faster')
    db.close()


def bench_full_build(tmp: Path, batch_size: int | None, workers: int) -> None:
    path = tmp / 'built.db'
    kwargs = {} if batch_size is None else {'batch_size': batch_size}
    t0 = time.perf_counter()
    db = build_knowledge_database(path, plant_factory=knowledge_plant, progress=True,
                                  workers=workers, **kwargs)
    wall = time.perf_counter() - t0
    print(
        f'full build           {wall:8.1f} s    {db.n_filled} points x 30 trials x 10 s,'
        f' batch {batch_size or "default"}, {workers} worker(s)   target <= {BUILD_TARGET_S:.0f} s'
        f'  {"OK" if wall <= BUILD_TARGET_S else "SLOW"}'
    )
    db.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--full-build', action='store_true', help='time the 67,200-point build')
    parser.add_argument('--batch-size', type=int, default=None, help='arms simulated at once')
    parser.add_argument('--workers', type=int, default=2, help='build processes (2 cores)')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bench_lookup_and_open(Path(tmp))
        if args.full_build:
            bench_full_build(Path(tmp), args.batch_size, args.workers)


if __name__ == '__main__':
    main()
