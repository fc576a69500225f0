"""What every benchmark shares: its result rows, the summary table and the round-robin timer.

A benchmark module ``benchmarks/bench_<name>.py`` exposes ``run(quick: bool) -> list[Row]``:
one `Row` per headline figure, with the baseline it was measured against in the same run and
its target, if it has one. ``benchmarks/run_all.py`` calls every module's ``run`` and prints one
table (`markdown_table`); each module's own ``main()`` prints its detailed report.

The ratio of a row is always figure / baseline (both in the row's unit): below 1 the figure is
smaller (faster, lighter) than its baseline. Targets are reported, never asserted.

Adding a benchmark: a new ``bench_<name>.py`` is picked up by ``run_all.py`` as it lands. Its
``run(quick=True)`` takes a few seconds (``tests/test_benchmarks.py`` runs them all), prints
nothing the table needs (its report is its ``main()``), raises on a real failure, and returns
``Row.skipped(name, reason)`` for a figure it cannot measure (an optional peer missing: see
`skip_reason_if_missing`). Time candidates with `interleaved`, the one timer here.
"""

from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass
import math
import statistics
import timeit

Statement = str | Callable[[], object] | timeit.Timer


@dataclass(frozen=True)
class Target:
    """Bounds a figure should meet; met when any one of the bounds given holds.

    Parameters
    ----------
    at_most, at_least : float, optional
        Bounds on the figure, in the row's unit.
    ratio_at_most : float, optional
        Bound on the ratio figure / baseline (the row needs a baseline).
    """

    at_most: float | None = None
    at_least: float | None = None
    ratio_at_most: float | None = None

    def __post_init__(self) -> None:
        bounds = (self.at_most, self.at_least, self.ratio_at_most)
        if all(b is None for b in bounds):
            raise ValueError('target: give at least one of at_most, at_least, ratio_at_most')
        for name, b in zip(('at_most', 'at_least', 'ratio_at_most'), bounds, strict=True):
            if b is not None and not math.isfinite(b):
                raise ValueError(f'target: {name} must be finite, got {b!r}')

    def text(self, unit: str) -> str:
        """The bounds as the table shows them, e.g. ``<= 25 us or <= 0.35x``."""
        sep = '' if unit in ('', '%') else ' '
        parts = []
        if self.at_most is not None:
            parts.append(f'<= {self.at_most:g}{sep}{unit}')
        if self.at_least is not None:
            parts.append(f'>= {self.at_least:g}{sep}{unit}')
        if self.ratio_at_most is not None:
            parts.append(f'<= {self.ratio_at_most:g}x')
        return ' or '.join(parts)

    def met(self, figure: float, ratio: float | None) -> bool:
        """Whether ``figure`` (and its ``ratio`` to the baseline, None without one) meets it."""
        return any((
            self.at_most is not None and figure <= self.at_most,
            self.at_least is not None and figure >= self.at_least,
            self.ratio_at_most is not None and ratio is not None and ratio <= self.ratio_at_most,
        ))


@dataclass(frozen=True)
class Row:
    """One figure of a benchmark, with its baseline and target.

    Parameters
    ----------
    name : str
        What was measured, e.g. ``'FlexibleArm.fk_and_jacobian, one call'``.
    figure : float or None
        The measured value in ``unit``; None when it was not measured (see `skipped`, and
        ``note`` for why).
    unit : str
        Unit of ``figure`` and ``baseline_figure``: ``'us'``, ``'ms'``, ``'s'``, ``'GiB'``,
        ``'%'``, ``''`` for counts.
    baseline : str
        What the figure is compared with ('' for none).
    baseline_figure : float, optional
        The baseline's value in the same unit, measured in the same run; > 0.
    target : Target, optional
        The figure's target, if it has one.
    note : str
        Conditions or context, and the reason for a skipped row.
    """

    name: str
    figure: float | None
    unit: str = ''
    baseline: str = ''
    baseline_figure: float | None = None
    target: Target | None = None
    note: str = ''

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError('name: must not be empty')
        if self.figure is not None and not math.isfinite(self.figure):
            raise ValueError(f'figure: {self.name}: must be finite or None, got {self.figure!r}')
        if self.baseline_figure is not None:
            if not (math.isfinite(self.baseline_figure) and self.baseline_figure > 0.0):
                raise ValueError(f'baseline_figure: {self.name}: must be finite and > 0, got '
                                 f'{self.baseline_figure!r}')
            if not self.baseline:
                raise ValueError(f'baseline: {self.name}: name the baseline of its figure')
        if self.target is not None and not isinstance(self.target, Target):
            raise ValueError(f'target: {self.name}: must be a Target, got {self.target!r}')
        if (self.target is not None and self.target.ratio_at_most is not None
                and self.figure is not None and self.baseline_figure is None):
            raise ValueError(f'target: {self.name}: a bound on the ratio needs a baseline_figure')

    @classmethod
    def skipped(cls, name: str, reason: str) -> 'Row':
        """A row for a figure that was not measured, and why (e.g. a peer is missing)."""
        if not reason:
            raise ValueError(f'reason: {name}: say why it was skipped')
        return cls(name, None, note=f'skipped: {reason}')

    @property
    def ratio(self) -> float | None:
        """figure / baseline_figure, or None without both."""
        if self.figure is None or self.baseline_figure is None:
            return None
        return self.figure / self.baseline_figure

    @property
    def met(self) -> bool | None:
        """Whether the figure meets its target; None without a target or a figure."""
        if self.target is None or self.figure is None:
            return None
        return self.target.met(self.figure, self.ratio)

    def to_dict(self) -> dict:
        """A JSON-ready dict (`from_dict` reads it back)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> 'Row':
        """The row of a `to_dict` dict."""
        fields = dict(data)
        if fields.get('target') is not None:
            fields['target'] = Target(**fields['target'])
        return cls(**fields)


def skip_reason_if_missing(*modules: str) -> str | None:
    """Why a benchmark of optional peers cannot run (the first module that does not import),
    or None when all import."""
    for module in modules:
        try:
            __import__(module)
        except ImportError:
            return f'{module} is not installed (pip install -r benchmarks/requirements.txt)'
    return None


# --- timing -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Timing:
    """Time per call of one candidate over the rounds of `interleaved`.

    Attributes
    ----------
    median_s, best_s, worst_s : float
        Median, smallest and largest time per call over the rounds [s].
    number : int
        Calls per round.
    rounds : int
        Rounds timed.
    """

    median_s: float
    best_s: float
    worst_s: float
    number: int
    rounds: int

    @property
    def median_us(self) -> float:
        """Median time per call [us]."""
        return self.median_s * 1e6

    @property
    def median_ms(self) -> float:
        """Median time per call [ms]."""
        return self.median_s * 1e3


def _calibrate(timer: timeit.Timer, min_time_s: float) -> int:
    """Calls per batch for a batch of about ``min_time_s``: after one warm-up call, batches of
    1, 10, 100, ... calls until one lasts a tenth of it, scaled.

    The warm-up call takes what only a first call costs (a compiled function loaded from its
    cache: ~0.1 s), which would otherwise set one call per batch, timed cold.
    """
    timer.timeit(1)
    n = 1
    while True:
        t = timer.timeit(n)
        if t >= 0.1 * min_time_s or n >= 10**8:
            return max(1, round(n * min_time_s / t)) if t > 0.0 else n
        n *= 10


def interleaved(
    candidates: Mapping[str, Statement],
    rounds: int,
    *,
    min_time_s: float = 0.02,
    number: int | None = None,
    namespace: Mapping | None = None,
) -> dict[str, Timing]:
    """Time each candidate round-robin: every round times one batch of calls of each in turn.

    Load from other processes on the machine then falls on all candidates alike, so their
    ratios stay meaningful on a shared machine; the median over rounds is the figure.

    Parameters
    ----------
    candidates : mapping of str to statement
        Name -> what to call: a zero-argument callable, a statement string (run in
        ``namespace``) or a `timeit.Timer` (e.g. with a setup that runs before every batch).
    rounds : int
        Rounds, >= 1.
    min_time_s : float
        Without ``number``: the length a batch is calibrated to [s] (the calibration also
        warms every candidate up).
    number : int, optional
        Calls per batch for every candidate, with no calibration and no warm-up call (for slow
        or stateful calls: warm them up before if needed).
    namespace : mapping, optional
        Globals of the statement strings.

    Returns
    -------
    dict of str to Timing
        Per candidate, in the order given.
    """
    if rounds < 1:
        raise ValueError(f'rounds: must be >= 1, got {rounds}')
    if number is not None and number < 1:
        raise ValueError(f'number: must be >= 1, got {number}')
    if min_time_s < 0.0:
        raise ValueError(f'min_time_s: must be >= 0, got {min_time_s}')
    timers = {name: stmt if isinstance(stmt, timeit.Timer)
              else timeit.Timer(stmt, globals=dict(namespace or {}))
              for name, stmt in candidates.items()}
    numbers = {}
    for name, timer in timers.items():
        numbers[name] = number if number is not None else _calibrate(timer, min_time_s)
    samples: dict[str, list[float]] = {name: [] for name in timers}
    for _ in range(rounds):
        for name, timer in timers.items():
            samples[name].append(timer.timeit(numbers[name]) / numbers[name])
    return {name: Timing(statistics.median(s), min(s), max(s), numbers[name], rounds)
            for name, s in samples.items()}


# --- the table ----------------------------------------------------------------------------------


def format_number(value: float) -> str:
    """About three significant digits, never in exponent form above 1e-3."""
    size = abs(value)
    if value == 0.0 or size >= 100.0:
        return f'{value:.0f}'
    if size >= 10.0:
        return f'{value:.1f}'
    if size >= 1.0:
        return f'{value:.2f}'
    if size >= 0.1:
        return f'{value:.3f}'
    if size >= 1e-3:
        return f'{value:.3g}'
    return f'{value:.2e}'


def format_value(value: float | None, unit: str) -> str:
    """A figure with its unit, e.g. ``2.43 us``; '' for None."""
    if value is None:
        return ''
    number = format_number(value)
    if not unit:
        return number
    return f'{number}{unit}' if unit == '%' else f'{number} {unit}'


TABLE_COLUMNS = ('benchmark', 'measured', 'figure', 'baseline', 'ratio', 'target', 'met', 'note')


def table_cells(benchmark: str, row: Row) -> tuple[str, ...]:
    """The cells of one row of the summary table, in `TABLE_COLUMNS` order."""
    baseline = ''
    if row.baseline:
        value = format_value(row.baseline_figure, row.unit)
        baseline = f'{value} ({row.baseline})' if value else row.baseline
    met = {None: '', True: 'yes', False: '**no**'}[row.met]
    figure = format_value(row.figure, row.unit) if row.figure is not None else '--'
    target = row.target.text(row.unit) if row.target is not None else ''
    ratio = format_number(row.ratio) if row.ratio is not None else ''
    return (benchmark, row.name, figure, baseline, ratio, target, met, row.note)


def markdown_table(rows: Iterable[tuple[str, Row]]) -> str:
    """One markdown table of ``(benchmark, row)`` pairs, columns padded to line up."""
    lines = [TABLE_COLUMNS] + [table_cells(benchmark, row) for benchmark, row in rows]
    lines = [tuple(cell.replace('|', '\\|') for cell in line) for line in lines]
    widths = [max(len(line[i]) for line in lines) for i in range(len(TABLE_COLUMNS))]

    def render(cells):
        return '| ' + ' | '.join(c.ljust(w) for c, w in zip(cells, widths, strict=True)) + ' |'

    rule = '| ' + ' | '.join('-' * w for w in widths) + ' |'
    return '\n'.join([render(lines[0]), rule, *map(render, lines[1:])])


def print_rows(benchmark: str, rows: Iterable[Row]) -> None:
    """Print a benchmark's rows as the summary table shows them (the end of its report)."""
    print(markdown_table((benchmark, row) for row in rows))
