"""The benchmark harness: benchmarks/run_all.py runs every bench_*.py and prints one table.

These tests check the harness, never a timing: every benchmark file has rows in the table of a
quick run, a crash (or a module without ``run``) fails the run, a missed target does not, and
the rows' protocol (benchmarks/common.py) validates its input.
"""

import os
import pathlib
import re
import subprocess
import sys
import textwrap
import time

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCHMARKS = REPO_ROOT / 'benchmarks'
sys.path.insert(0, str(BENCHMARKS))

from common import Row, Target, interleaved, markdown_table  # noqa: E402

CELL_SEPARATOR = re.compile(r'(?<!\\)\|')


def run_all(*args: str, env: dict | None = None, timeout_s: float = 240.0):
    return subprocess.run([sys.executable, str(BENCHMARKS / 'run_all.py'), *args],
                          cwd=REPO_ROOT, env=dict(os.environ, **(env or {})),
                          capture_output=True, text=True, timeout=timeout_s)


def table_rows(stdout: str) -> list[dict[str, str]]:
    """The rows of the markdown table in ``stdout``, as column -> cell."""
    lines = [line for line in stdout.splitlines() if line.startswith('| ')]
    assert len(lines) >= 2, f'no table in:\n{stdout}'
    split = [[cell.strip() for cell in CELL_SEPARATOR.split(line)[1:-1]] for line in lines]
    header, rule, body = split[0], split[1], split[2:]
    assert header[:3] == ['benchmark', 'measured', 'figure'], header
    assert all(set(cell) == {'-'} for cell in rule), rule
    return [dict(zip(header, cells, strict=True)) for cells in body]


@pytest.mark.system
def test_a_quick_run_has_rows_of_every_benchmark_file_and_exits_0(domain_id):
    result = run_all('--quick', env={'ROS_DOMAIN_ID': str(domain_id)})
    assert result.returncode == 0, result.stdout + result.stderr
    rows = table_rows(result.stdout)
    names = {path.stem.removeprefix('bench_') for path in BENCHMARKS.glob('bench_*.py')}
    assert names, 'no benchmarks found'
    assert {row['benchmark'] for row in rows} == names
    for row in rows:
        # A figure, or a row that says why it was skipped; nothing crashed.
        assert row['figure'] != '--' or row['note'].startswith('skipped: '), row
        assert not row['measured'].startswith(('crashed', 'timed out')), row
        assert row['met'] in ('', 'yes', '**no**'), row
    assert re.search(rf'{len(names)} benchmarks, {len(rows)} rows', result.stdout)


def test_a_crash_or_a_module_without_run_fails_the_run_and_a_missed_target_does_not(tmp_path):
    (tmp_path / 'bench_good.py').write_text(textwrap.dedent("""
        from common import Row, Target

        def run(quick):
            return [Row('speed', 2.0, 'us', 'floor', 1.0, Target(ratio_at_most=1.5)),
                    Row.skipped('against a peer', 'peer is not installed')]
    """))
    (tmp_path / 'bench_broken.py').write_text(textwrap.dedent("""
        def run(quick):
            raise RuntimeError('the benchmark broke')
    """))
    (tmp_path / 'bench_old.py').write_text('def main():\n    print("own report")\n')
    (tmp_path / 'helper.py').write_text('raise RuntimeError("not a benchmark")\n')

    result = run_all('--quick', '--directory', str(tmp_path), timeout_s=60.0)
    assert result.returncode == 1, result.stdout + result.stderr
    rows = {(row['benchmark'], row['measured']): row for row in table_rows(result.stdout)}
    assert set(rows) == {('broken', 'crashed (exit code 1)'), ('good', 'speed'),
                         ('good', 'against a peer'), ('old', 'crashed (exit code 1)')}
    assert rows['broken', 'crashed (exit code 1)']['note'] == (
        'RuntimeError: the benchmark broke')
    assert 'has no run(quick)' in rows['old', 'crashed (exit code 1)']['note']
    speed = rows['good', 'speed']
    assert (speed['figure'], speed['baseline'], speed['ratio'], speed['target'],
            speed['met']) == ('2.00 us', '1.00 us (floor)', '2.00', '<= 1.5x', '**no**')
    assert rows['good', 'against a peer']['note'] == 'skipped: peer is not installed'
    assert 'FAILED: broken, old' in result.stdout

    only = run_all('--only', 'good', '--directory', str(tmp_path), timeout_s=60.0)
    assert only.returncode == 0, only.stdout + only.stderr
    assert 'targets met 0 of 1 (missed: good: speed)' in only.stdout

    unknown = run_all('--only', 'nothing', '--directory', str(tmp_path), timeout_s=60.0)
    assert unknown.returncode == 2
    assert '--only: no benchmark named nothing' in unknown.stderr


def test_a_target_is_met_when_any_of_its_bounds_holds():
    target = Target(at_most=25.0, ratio_at_most=0.35)
    assert target.text('us') == '<= 25 us or <= 0.35x'
    assert Row('warm', 30.0, 'us', 'cold', 100.0, target).met  # ratio 0.3
    assert Row('warm', 20.0, 'us', 'cold', 40.0, target).met  # 20 us
    assert not Row('warm', 30.0, 'us', 'cold', 40.0, target).met
    assert Row('count', 3, '', target=Target(at_least=3)).met
    assert Row('no target', 1.0, 's').met is None
    assert Row.skipped('peer', 'not installed').met is None
    assert Row('x', 1.0, 's', 'y', 4.0).ratio == 0.25


@pytest.mark.parametrize(('kwargs', 'message'), [
    ({'name': '', 'figure': 1.0}, 'name: must not be empty'),
    ({'name': 'x', 'figure': float('nan')}, 'figure: x: must be finite'),
    ({'name': 'x', 'figure': 1.0, 'baseline': 'y', 'baseline_figure': 0.0},
     'baseline_figure: x: must be finite and > 0'),
    ({'name': 'x', 'figure': 1.0, 'baseline_figure': 2.0}, 'baseline: x: name the baseline'),
    ({'name': 'x', 'figure': 1.0, 'target': Target(ratio_at_most=1.0)},
     'target: x: a bound on the ratio needs a baseline_figure'),
    ({'name': 'x', 'figure': 1.0, 'target': '<= 1'}, 'target: x: must be a Target'),
])
def test_a_row_rejects_what_it_cannot_report(kwargs, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        Row(**kwargs)


def test_a_target_needs_a_finite_bound_and_a_skip_a_reason():
    with pytest.raises(ValueError, match='target: give at least one of'):
        Target()
    with pytest.raises(ValueError, match='target: at_most must be finite'):
        Target(at_most=float('inf'))
    with pytest.raises(ValueError, match='reason: x: say why'):
        Row.skipped('x', '')


def test_rows_survive_the_json_between_processes_and_pipes_are_escaped():
    row = Row('a | b', 2.5, 'ms', 'c', 5.0, Target(at_most=3.0), 'n')
    assert Row.from_dict(row.to_dict()) == row
    table = markdown_table([('bench', row)])
    header, rule, line = table.splitlines()
    assert len(CELL_SEPARATOR.split(line)) == len(CELL_SEPARATOR.split(header))
    assert 'a \\| b' in line and '2.50 ms' in line and '0.500' in line


def test_interleaved_times_every_candidate_in_its_order():
    calls = []
    timing = interleaved({'b': lambda: calls.append('b'), 'a': lambda: calls.append('a')},
                         rounds=3, number=2)
    assert list(timing) == ['b', 'a']
    assert calls == ['b', 'b', 'a', 'a'] * 3  # round-robin, no warm-up with a number given
    assert all(0.0 < t.best_s <= t.median_s <= t.worst_s and t.number == 2 for t in
               timing.values())
    with pytest.raises(ValueError, match='rounds: must be >= 1'):
        interleaved({'a': lambda: None}, rounds=0)


def test_a_slow_first_call_does_not_set_the_batch_size():
    # like a compiled function loaded from its cache on its first call
    calls = []

    def candidate():
        if not calls:
            time.sleep(0.05)
        calls.append(None)

    timing = interleaved({'first call slow': candidate}, rounds=1, min_time_s=0.01)
    assert timing['first call slow'].number > 10  # 1 when the slow call calibrated it
