"""Run every benchmark and print one table of its figures and ratios against their baselines.

Usage: ``scripts/bench [--quick] [--only NAME ...] [--verbose]`` (it sets up the workspace and
the benchmarks' peers first), or ``source scripts/env.sh && python benchmarks/run_all.py ...``.

Every ``benchmarks/bench_*.py`` is found and run, one at a time, each in a Python process of
its own (so that one's state, threads or crash cannot touch another's timings): the process
calls the module's ``run(quick)``, which returns `common.Row` objects. The table (markdown, on
stdout) has a row per figure: benchmark, what was measured, the figure, the baseline measured
in the same run, the ratio figure / baseline, the target and whether it is met, and a note. A
figure that could not be measured (a missing optional peer, such as tcod) is a row saying it
was skipped and why. Progress, and the output of a benchmark that failed, go to stderr.

Time on the shared 2-core machine: ``--quick`` (a few seconds a benchmark, for CI smoke) about
40 s; the full run about 9 min, 15 min when the machine is busy: planning ~2.5 min (1 mm
grids, tcod, heapq), knowledge ~3 min (the full 67,200-point build, the Dask scaling),
elastostatic ~15-30 s (with its ambiguity search), load_estimator ~5 min (eight runs of 20 s),
vision ~25 s, the others ~10 s each.

Exit code 0 when every benchmark ran, whether its targets were met or not (targets are
reported, not asserted); 1 when one crashed, timed out or has no ``run(quick)``.
"""

import argparse
import importlib
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

from common import Row, markdown_table

HERE = Path(__file__).resolve().parent
PREFIX = 'bench_'


def discover(directory: Path) -> list[Path]:
    """The benchmark modules of ``directory``: ``bench_*.py``, sorted by name."""
    return sorted(directory.glob(f'{PREFIX}*.py'))


def short_name(path: Path) -> str:
    """``bench_kinematics.py`` -> ``kinematics``: the benchmark column of the table."""
    return path.stem.removeprefix(PREFIX)


def child(path: Path, quick: bool, rows_out: Path) -> int:
    """In the benchmark's own process: import it, call ``run(quick)``, write its rows as JSON."""
    sys.path.insert(0, str(path.parent))
    module = importlib.import_module(path.stem)
    run = getattr(module, 'run', None)
    if not callable(run):
        raise SystemExit(f'{path.name} has no run(quick) -> list[Row] (benchmarks/common.py)')
    rows = run(quick=quick)
    if not isinstance(rows, list) or not all(isinstance(row, Row) for row in rows):
        raise SystemExit(f'{path.name}: run(quick) returned {type(rows).__name__}, not a list '
                         f'of common.Row')
    if not rows:
        raise SystemExit(f'{path.name}: run(quick) returned no rows')
    rows_out.write_text(json.dumps([row.to_dict() for row in rows]))
    return 0


def failure_row(what: str, output: str) -> Row:
    """The row of a benchmark that did not finish, with the last line it printed."""
    lines = [line for line in output.splitlines() if line.strip()]
    return Row(what, None, note=lines[-1].strip() if lines else 'no output')


def run_one(path: Path, quick: bool, timeout_s: float, verbose: bool) -> tuple[list[Row], bool]:
    """Run one benchmark in a process of its own: its rows, and whether it finished."""
    with tempfile.TemporaryDirectory(prefix='inflarm-bench-') as tmp:
        rows_out, log = Path(tmp) / 'rows.json', Path(tmp) / 'output.txt'
        command = [sys.executable, str(Path(__file__).resolve()), '--child', str(path),
                   '--rows-out', str(rows_out)] + (['--quick'] if quick else [])
        with open(log, 'w') as output:
            redirect = {} if verbose else {'stdout': output, 'stderr': subprocess.STDOUT}
            process = subprocess.Popen(command, stdin=subprocess.DEVNULL,
                                       start_new_session=True, **redirect)
            try:
                code = process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
                code = None
        text = log.read_text(errors='replace')
        if code == 0 and rows_out.exists():
            return [Row.from_dict(d) for d in json.loads(rows_out.read_text())], True
    if text:
        print(f'--- {path.name}: last lines of its output\n' + '\n'.join(
            text.splitlines()[-30:]), file=sys.stderr)
    if code is None:
        return [failure_row('timed out', f'no rows after {timeout_s:g} s (--timeout)')], False
    return [failure_row(f'crashed (exit code {code})', text)], False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='a few seconds a benchmark (CI smoke); default: the full run')
    parser.add_argument('--only', nargs='+', metavar='NAME', default=None,
                        help='run only these benchmarks (e.g. kinematics planning)')
    parser.add_argument('--verbose', action='store_true',
                        help="show each benchmark's own output as it runs")
    parser.add_argument('--timeout', type=float, default=None,
                        help='seconds a benchmark may take (default 300 quick, 1800 full)')
    parser.add_argument('--directory', type=Path, default=HERE,
                        help='where the bench_*.py files are (default: this folder)')
    parser.add_argument('--child', type=Path, help=argparse.SUPPRESS)
    parser.add_argument('--rows-out', type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return child(args.child, args.quick, args.rows_out)

    paths = discover(args.directory)
    if args.only is not None:
        unknown = set(args.only) - {short_name(p) for p in paths}
        if unknown:
            parser.error(f'--only: no benchmark named {", ".join(sorted(unknown))} in '
                         f'{args.directory} (have {", ".join(map(short_name, paths))})')
        paths = [p for p in paths if short_name(p) in args.only]
    if not paths:
        parser.error(f'no {PREFIX}*.py in {args.directory}')
    timeout_s = args.timeout or (300.0 if args.quick else 1800.0)
    mode = 'quick' if args.quick else 'full'

    table: list[tuple[str, Row]] = []
    failed = []
    started = time.monotonic()
    for i, path in enumerate(paths, 1):
        name = short_name(path)
        print(f'[{i}/{len(paths)}] {name} ({mode}) ...', file=sys.stderr, flush=True)
        t0 = time.monotonic()
        rows, finished = run_one(path, args.quick, timeout_s, args.verbose)
        if not finished:
            failed.append(name)
        print(f'[{i}/{len(paths)}] {name}: {len(rows)} row(s) in {time.monotonic() - t0:.1f} s'
              + ('' if finished else ', FAILED'), file=sys.stderr, flush=True)
        table += [(name, row) for row in rows]

    print(f'Benchmarks, {mode} run: ratio = figure / baseline, both measured in this run.')
    print()
    print(markdown_table(table))
    targets = [(name, row) for name, row in table if row.met is not None]
    missed = [f'{name}: {row.name}' for name, row in targets if not row.met]
    print()
    print(f'{len(paths)} benchmarks, {len(table)} rows in {time.monotonic() - started:.0f} s; '
          f'targets met {len(targets) - len(missed)} of {len(targets)}'
          + (f' (missed: {"; ".join(missed)})' if missed else ''))
    if failed:
        print(f'FAILED: {", ".join(failed)} (output above, on stderr)')
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
