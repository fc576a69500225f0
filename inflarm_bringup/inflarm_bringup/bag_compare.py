"""Recorded against replayed messages, topic by topic: counts, matches, per-field differences.

The pure half of the bag regression (``inflarm_bringup.bag_regression``): no rclpy. Messages
are `inflarm_hw.bag.BagMessage` tuples (CDR bytes and a record or publish time), decoded with
the ``rosbags`` Jazzy typestore on both sides, so both are read by one decoder.

Matching. Messages with a header stamp on both sides are matched by stamp, the others by time
(record time in the bag, publish time in the replay). Both sequences are sorted by that key and
merged in order: a recorded and a replayed message are a match when their keys differ by at
most half the median spacing of the recorded keys (any difference when a topic holds a single
message), so that a stream at a fixed rate never pairs a message with its neighbour. What
is left over on either side is unmatched, except replayed messages outside the span of the
recorded ones (by more than that window): a recorder sees a topic only from when it
subscribed to it until it stopped, while the replay runs over the whole bag. They are counted
as ``outside``. A topic with a ``match_window`` tolerance [s] (``/link_status``: 0.1 s, one
period) is instead paired one to one, nearest in time first, with recorded messages of the same
names within that window (and its ``alternative`` is the nearest one). Within the window a
message is paired only with one of the same names and frames (its exact fields: e.g. the link
of a LinkStatus), so a lost one does not shift the rest. ``from_ns`` leaves a topic's start-up
out on both sides (``skipped``). For a timer's outputs (``neighbours``), a recorded message out
of tolerance against its replayed one may match the ``alternative`` replay's message of the
same key instead (its ambiguous inputs in the other order: ``by_alternative``); one out of
tolerance in both counts as unmatched (``out_of_tolerance``), within the ``unmatched`` share.

Fields. Each message is flattened into leaves (``position[2]``, ``wrench.force.x``; for inflarm
JSON messages in ``std_msgs/String``, the JSON fields: ``chambers.B1``, ``rmse[0]``), grouped by
field (``position``, ``wrench.force``, ``chambers``) and each group has a quantity
(`QUANTITIES`): position [m or rad], velocity, force [N], torque [N m], pressure [Pa], time [s],
ratio [1]. A group without one (names, frames, integers, strings) must be equal. A leaf on
one side only, a ``null`` against a number, or unequal text is an infinite difference. The
header stamp is the match key and is not compared.

Tolerances (`Tolerances`) are absolute, in SI units, per quantity and optionally per topic
(``/estimated_wrench:force``); ``unmatched`` is the share of messages of a topic (of the larger
count) that may be left unmatched, e.g. a sample a best-effort recorder lost; ``match_window``
[s], where given for a topic, pairs by nearest time within it (0: half the median spacing).
"""

import bisect
from collections.abc import Iterable, Mapping, Sequence
import csv
from dataclasses import dataclass, field, fields, is_dataclass
import io
import json
import math

import numpy as np

from inflarm_hw.bag import BagMessage, deserialize, normalize_topic

__all__ = [
    'DEFAULT_TOLERANCES',
    'QUANTITIES',
    'UNITS',
    'FieldDifference',
    'Report',
    'TopicComparison',
    'Tolerances',
    'compare',
    'flatten',
    'stamp_ns',
]

STRING = 'std_msgs/msg/String'
# Messages whose x/y/z(/w) are one field group (a point, a force), not three.
VECTOR_TYPES = frozenset({'geometry_msgs/msg/Point', 'geometry_msgs/msg/Point32',
                          'geometry_msgs/msg/Vector3', 'geometry_msgs/msg/Quaternion'})
JSON_ENVELOPE = ('type', 'schema_version')
_MISSING = object()  # a leaf on one side only

#: (message kind, field group) -> quantity. The kind is the ROS type, or for inflarm JSON
#: messages their ``type``. Groups not listed must be equal.
QUANTITIES: Mapping[tuple[str, str], str] = {
    ('sensor_msgs/msg/JointState', 'position'): 'position',
    ('sensor_msgs/msg/JointState', 'velocity'): 'velocity',
    ('sensor_msgs/msg/JointState', 'effort'): 'torque',
    ('geometry_msgs/msg/WrenchStamped', 'wrench.force'): 'force',
    ('geometry_msgs/msg/WrenchStamped', 'wrench.torque'): 'torque',
    ('geometry_msgs/msg/PointStamped', 'point'): 'position',
    ('PressureCommand', 'chambers'): 'pressure',
    ('ChamberPressures', 'chambers'): 'pressure',
    ('TrialReport', 'rmse'): 'position',
    ('TrialReport', 'reach_time'): 'time',
    ('LinkStatus', 'pressure'): 'pressure',
    ('LinkStatus', 'wrinkling_moment'): 'torque',
    ('LinkStatus', 'moment'): 'torque',
    ('LinkStatus', 'margin'): 'torque',  # wrinkling_moment - moment [N m]
}
#: Unit of each quantity, for the report.
UNITS: Mapping[str, str] = {
    'position': 'm|rad', 'velocity': 'm/s|rad/s', 'force': 'N', 'torque': 'N m',
    'pressure': 'Pa', 'time': 's', 'ratio': '1', 'exact': '', 'unmatched': 'share',
    'match_window': 's',
}


@dataclass(frozen=True)
class Tolerances:
    """Absolute tolerances [SI] by quantity, with per-topic overrides.

    Attributes
    ----------
    values : mapping of str to float
        ``'<quantity>'`` or ``'<topic>:<quantity>'`` (fully qualified topic) -> tolerance;
        quantities as in `UNITS`. ``'exact'`` is always 0.
    """

    values: Mapping[str, float]

    def __post_init__(self) -> None:
        for key, value in self.values.items():
            quantity = key.rpartition(':')[2]
            if quantity not in UNITS:
                raise ValueError(f'tolerance {key!r}: unknown quantity {quantity!r}, expected '
                                 f'one of {sorted(UNITS)}')
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f'tolerance {key!r}: expected a finite number >= 0, got '
                                 f'{value!r}')
            if quantity == 'unmatched' and value > 1.0:
                raise ValueError(f'tolerance {key!r}: a share of messages, at most 1, got '
                                 f'{value!r}')

    def of(self, topic: str, quantity: str) -> float:
        """The tolerance of ``quantity`` on ``topic`` (the topic's own, else the quantity's)."""
        if quantity == 'exact':
            return 0.0
        return float(self.values.get(f'{topic}:{quantity}', self.values.get(quantity, 0.0)))

    def updated(self, specs: Iterable[str]) -> 'Tolerances':
        """These tolerances with ``specs`` (``'force=0.01'``, ``'estimated_wrench:force=0.1'``)
        applied.

        Raises
        ------
        ValueError
            On a spec that is not ``[TOPIC:]QUANTITY=VALUE`` with a known quantity and a
            number >= 0.
        """
        values = dict(self.values)
        for spec in specs:
            key, sep, text = spec.partition('=')
            topic, colon, quantity = key.strip().rpartition(':')
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not sep or not quantity or not math.isfinite(value):
                raise ValueError(f'tolerance {spec!r}: expected [TOPIC:]QUANTITY=VALUE, e.g. '
                                 "'force=0.01' or 'estimated_wrench:force=0.1'")
            values[f'{normalize_topic(topic)}:{quantity}' if colon else quantity] = value
        return Tolerances(values)


#: The defaults: absolute tolerances per quantity, overridden per topic where a topic needs its
#: own, set between the replay-to-replay differences of a recorded run and what a changed
#: parameter moves (``inflarm_bringup/README.md`` has the figures).
DEFAULT_TOLERANCES = Tolerances({
    'position': 1e-4, 'velocity': 1e-3, 'force': 1e-3, 'torque': 1e-3, 'pressure': 100.0,
    'time': 0.25, 'ratio': 1e-4, 'unmatched': 0.05,
    # A trial's RMSE over its N steps (20 in a 4 s trial at 5 Hz): one step that took the
    # 20 Hz ball sample next to the recorded one (ordering ambiguity) changes one error by
    # the ball's motion in 50 ms, delta (up to ~4 mm at the trial's start), and the RMSE by at
    # most delta / sqrt(N) ~ 1 mm; a changed controller moves it by centimetres.
    '/trial_report:position': 1e-3,
    # elastostatic_ik plans a whole path from one load estimate, the latest when the path
    # arrives; which one is latest is a sub-millisecond ordering the record cannot fix, and
    # one estimate's sample-to-sample noise moves the plan. 1e-3 rad (0.6 mm at the tip of a
    # 0.6 m link) is above that and below what a 10 % stiffer IK model moves it by (README).
    '/motor_position_command:position': 1e-3,
    # The load estimator's 10 Hz link status publishes only when a new estimate arrived since
    # its last firing: whether a firing publishes is the same ordering ambiguity. Its messages
    # are matched to the nearest recorded one of the same link within one period (0.1 s), the
    # matched values compared, and up to 15 % of them may be unmatched (a count difference).
    '/link_status:match_window': 0.1,
    '/link_status:unmatched': 0.15,
})


@dataclass(frozen=True)
class FieldDifference:
    """The largest difference of one field group over the matched messages of a topic.

    group : str (``'wrench.force'``); quantity : str (`UNITS`); max_abs_diff : float [SI]
    (inf: a value on one side only, or unequal text); tolerance : float; worst_key_ns : int,
    the match key (stamp or time [ns]) of the recorded message where it is largest.
    """

    group: str
    quantity: str
    max_abs_diff: float
    tolerance: float
    worst_key_ns: int

    @property
    def passed(self) -> bool:
        return self.max_abs_diff <= self.tolerance


@dataclass(frozen=True)
class TopicComparison:
    """One output topic, recorded against replayed."""

    topic: str
    msgtype: str
    key: str  # 'stamp' or 'time': what messages were matched by
    recorded: int
    replayed: int
    matched: int
    unmatched_tolerance: float
    outside: int = 0  # replayed messages outside the recorded span: not matched, not counted
    fields: tuple[FieldDifference, ...] = ()
    problems: tuple[str, ...] = ()  # messages that could not be decoded, type mismatches
    skipped: int = 0  # recorded messages in the start-up period: not compared, not counted
    by_alternative: int = 0  # recorded messages matched by the other order's replay
    out_of_tolerance: int = 0  # paired, out of tolerance in both orders: unmatched

    @property
    def unmatched_share(self) -> float:
        total = max(self.recorded, self.replayed - self.outside)
        return 0.0 if total == 0 else 1.0 - self.matched / total

    @property
    def passed(self) -> bool:
        return (not self.problems and self.unmatched_share <= self.unmatched_tolerance
                and (self.matched > 0 or self.recorded == self.replayed == 0)
                and all(f.passed for f in self.fields))

    def failures(self) -> list[str]:
        """What is out of tolerance, in words."""
        out = list(self.problems)
        if self.matched == 0 and (self.recorded or self.replayed):
            out.append(f'no message matched ({self.recorded} recorded, {self.replayed} '
                       'replayed' + (f', {self.out_of_tolerance} paired but out of tolerance '
                                     'in both input orders' if self.out_of_tolerance else '')
                       + ')')
        elif self.unmatched_share > self.unmatched_tolerance:
            out.append(f'{self.unmatched_share:.1%} of the messages unmatched (tolerance '
                       f'{self.unmatched_tolerance:.1%}): {self.recorded} recorded, '
                       f'{self.replayed - self.outside} replayed in their span, '
                       f'{self.matched} matched'
                       + (f', {self.out_of_tolerance} paired but out of tolerance in both '
                          'input orders' if self.out_of_tolerance else ''))
        for f in self.fields:
            if not f.passed:
                unit = UNITS[f.quantity]
                out.append(f'{f.group} differs by {f.max_abs_diff:.4g}{" " + unit if unit else ""}'
                           f' (tolerance {f.tolerance:g}) at {f.worst_key_ns * 1e-9:.6f} s')
        return out


@dataclass(frozen=True)
class Report:
    """Every compared topic; ``passed`` when each is within its tolerances."""

    topics: tuple[TopicComparison, ...]
    not_compared: tuple[str, ...] = field(default=())  # topics replayed but not recorded

    @property
    def passed(self) -> bool:
        return bool(self.topics) and all(t.passed for t in self.topics)

    def failed_topics(self) -> list[str]:
        return [t.topic for t in self.topics if not t.passed]

    def rows(self) -> list[dict[str, object]]:
        """One row per topic and field group (a topic without fields: one row)."""
        rows = []
        for t in self.topics:
            base = {'topic': t.topic, 'type': t.msgtype, 'key': t.key, 'recorded': t.recorded,
                    'replayed': t.replayed, 'outside': t.outside, 'matched': t.matched}
            for f in t.fields or (None,):
                rows.append({**base,
                             'field': '' if f is None else f.group,
                             'quantity': '' if f is None else f.quantity,
                             'unit': '' if f is None else UNITS[f.quantity],
                             'max_abs_diff': '' if f is None else f.max_abs_diff,
                             'tolerance': '' if f is None else f.tolerance,
                             'ok': t.passed if f is None else f.passed})
        return rows

    def table(self) -> str:
        """The report as a fixed-width text table, then the failures."""
        header = ('topic', 'key', 'recorded', 'replayed', 'outside', 'matched', 'field',
                  'max |diff|', 'tolerance', 'ok')
        lines = [[str(r['topic']), str(r['key']), str(r['recorded']), str(r['replayed']),
                  str(r['outside']), str(r['matched']), _field_label(r),
                  _number(r['max_abs_diff']), _number(r['tolerance']),
                  'ok' if r['ok'] else 'FAIL'] for r in self.rows()]
        widths = [max(len(h), *(len(line[i]) for line in lines)) if lines else len(h)
                  for i, h in enumerate(header)]
        text = [_row(header, widths), _row(['-' * w for w in widths], widths)]
        text += [_row(line, widths) for line in lines]
        text += self._summary()
        return '\n'.join(text)

    def markdown(self) -> str:
        """The report as a markdown table, then the failures."""
        header = ('topic', 'key', 'recorded', 'replayed', 'outside', 'matched', 'field',
                  'max \\|diff\\|', 'tolerance', 'ok')
        text = ['| ' + ' | '.join(header) + ' |', '|' + ' --- |' * len(header)]
        for r in self.rows():
            text.append('| ' + ' | '.join((
                f"`{r['topic']}`", str(r['key']), str(r['recorded']), str(r['replayed']),
                str(r['outside']), str(r['matched']), _field_label(r), _number(r['max_abs_diff']),
                _number(r['tolerance']), 'ok' if r['ok'] else '**FAIL**')) + ' |')
        return '\n'.join(text + [''] + [f'- {line}' for line in self._summary()]) + '\n'

    def csv(self) -> str:
        """The report's rows as CSV (max_abs_diff and tolerance in the unit column's unit)."""
        out = io.StringIO()
        writer = csv.DictWriter(out, fieldnames=['topic', 'type', 'key', 'recorded', 'replayed',
                                                 'outside', 'matched', 'field', 'quantity', 'unit',
                                                 'max_abs_diff', 'tolerance', 'ok'])
        writer.writeheader()
        for row in self.rows():
            writer.writerow({k: repr(v) if isinstance(v, float) else v for k, v in row.items()})
        return out.getvalue()

    def _summary(self) -> list[str]:
        lines = []
        for t in self.topics:
            lines += [f'FAIL {t.topic}: {failure}' for failure in t.failures()]
        if self.not_compared:
            lines.append(f"not compared (not in the bag): {', '.join(self.not_compared)}")
        if self.passed:
            lines.append(f'PASS: {len(self.topics)} topics within tolerance')
        elif not self.topics:
            lines.append('FAIL: no topic to compare')
        else:
            lines.append(f"FAIL: {', '.join(self.failed_topics())} out of tolerance")
        return lines


def _field_label(row: Mapping[str, object]) -> str:
    if not row['field']:
        return ''
    unit = row['unit']
    return f"{row['field']} [{unit}]" if unit else str(row['field'])


def _number(value: object) -> str:
    return f'{value:.3g}' if isinstance(value, float) else str(value)


def _row(cells: Sequence[str], widths: Sequence[int]) -> str:
    first = cells[0].ljust(widths[0])
    rest = [c.rjust(w) if i not in (0, 5) else c.ljust(w)
            for i, (c, w) in enumerate(zip(cells[1:], widths[1:], strict=True))]
    return '  '.join([first, *rest]).rstrip()


# -- flattening ----------------------------------------------------------------------------------

Leaf = float | int | bool | str | None


def flatten(message: object, msgtype: str) -> tuple[str, dict[str, tuple[str, Leaf]]]:
    """A decoded message as ``(kind, {leaf path: (field group, value)})``, header stamp left out.

    Parameters
    ----------
    message : rosbags message
        As `inflarm_hw.bag.deserialize` returns it.
    msgtype : str
        Its ROS type.

    Returns
    -------
    kind : str
        ``msgtype``, or the ``type`` of an inflarm JSON message carried in a ``std_msgs/String``.
    leaves : dict
        Leaf path (``'wrench.force.x'``, ``'position[1]'``, ``'chambers.B1'``) -> (group, value).
    """
    leaves: dict[str, tuple[str, Leaf]] = {}
    if msgtype == STRING:
        try:
            body = json.loads(message.data)
        except ValueError:
            body = None
        if isinstance(body, dict) and isinstance(body.get('type'), str):
            for key, value in body.items():
                if key not in JSON_ENVELOPE:  # the kind says which type it is
                    _flatten_json(value, key, key, leaves)
            return body['type'], leaves
    _flatten_ros(message, '', None, leaves)
    leaves.pop('header.stamp.sec', None)
    leaves.pop('header.stamp.nanosec', None)
    return msgtype, leaves


def _flatten_ros(value: object, path: str, group: str | None,
                 leaves: dict[str, tuple[str, Leaf]]) -> None:
    if is_dataclass(value):
        if group is None and path and getattr(value, '__msgtype__', '') in VECTOR_TYPES:
            group = path
        for f in fields(value):
            if f.name.startswith('__'):  # rosbags' __msgtype__
                continue
            _flatten_ros(getattr(value, f.name), f'{path}.{f.name}' if path else f.name, group,
                         leaves)
    elif isinstance(value, (np.ndarray, list, tuple)):
        for i, item in enumerate(value.tolist() if isinstance(value, np.ndarray) else value):
            _flatten_ros(item, f'{path}[{i}]', group or path, leaves)
    else:
        leaves[path] = (group or path, value.item() if isinstance(value, np.generic) else value)


def _flatten_json(value: object, path: str, group: str,
                  leaves: dict[str, tuple[str, Leaf]]) -> None:
    if isinstance(value, dict):
        for key, item in value.items():
            _flatten_json(item, f'{path}.{key}', group, leaves)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _flatten_json(item, f'{path}[{i}]', group, leaves)
    else:
        leaves[path] = (group, value)


def _difference(a: Leaf, b: Leaf) -> float:
    numeric = (int, float)
    if (isinstance(a, numeric) and isinstance(b, numeric) and not isinstance(a, bool)
            and not isinstance(b, bool)):
        d = abs(float(a) - float(b))
        return 0.0 if math.isnan(a) and math.isnan(b) else (math.inf if math.isnan(d) else d)
    return 0.0 if a == b else math.inf


# -- matching ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Decoded:
    key_ns: int
    kind: str
    leaves: dict[str, tuple[str, Leaf]]


def stamp_ns(message: object) -> int | None:
    """The header stamp [ns] of a decoded message, or None when it has no header."""
    stamp = getattr(getattr(message, 'header', None), 'stamp', None)
    return None if stamp is None else stamp.sec * 10**9 + stamp.nanosec


def _decode(messages: Sequence[BagMessage], problems: list[str], side: str
            ) -> list[tuple[BagMessage, object]]:
    out = []
    for m in messages:
        try:
            out.append((m, deserialize(m.data, m.msgtype)))
        except ValueError as err:
            problems.append(f'{side} message at {m.timestamp_ns * 1e-9:.6f} s: {err}')
    return out


def _match_window(keys: Sequence[int]) -> float:
    if len(keys) < 2:
        return math.inf
    spacing = float(np.median(np.diff(np.sort(np.asarray(keys, dtype=np.int64)))))
    return max(spacing / 2.0, 1.0)


def _signature(d: _Decoded) -> tuple:
    # What must be equal (names, frames, links): a message is only ever paired with one of
    # the same signature.
    return tuple(sorted((path, repr(value)) for path, (group, value) in d.leaves.items()
                        if QUANTITIES.get((d.kind, group), 'exact') == 'exact'))


def _differences(a: _Decoded, b: _Decoded) -> dict[str, tuple[str, float]]:
    out: dict[str, tuple[str, float]] = {}
    for path in a.leaves.keys() | b.leaves.keys():
        group = (a.leaves.get(path) or b.leaves[path])[0]
        left = a.leaves.get(path, (group, _MISSING))[1]
        right = b.leaves.get(path, (group, _MISSING))[1]
        diff = math.inf if _MISSING in (left, right) else _difference(left, right)
        quantity = QUANTITIES.get((a.kind, group), 'exact')
        if group not in out or diff > out[group][1]:
            out[group] = (quantity, diff)
    return out


def _badness(diffs: Mapping[str, tuple[str, float]], topic: str,
             tolerances: Tolerances) -> float:
    # The largest difference in tolerances (0: equal; > 1: out of tolerance).
    worst = 0.0
    for quantity, diff in diffs.values():
        tol = tolerances.of(topic, quantity)
        worst = max(worst, (0.0 if diff == 0 else math.inf) if tol == 0 else diff / tol)
    return worst


def _nearest_pairs(a: Sequence[_Decoded], b: Sequence[_Decoded], sig_a: Sequence[tuple],
                   sig_b: Sequence[tuple], window: float) -> list[tuple[int, int]]:
    # One-to-one pairs (i, j) of a recorded and a replayed message of the same signature
    # within ``window`` [ns] of each other, the nearest first (greedy by time difference).
    keys_b = [d.key_ns for d in b]
    candidates = []
    for i, d in enumerate(a):
        lo = bisect.bisect_left(keys_b, d.key_ns - window)
        hi = bisect.bisect_right(keys_b, d.key_ns + window)
        candidates += [(abs(keys_b[j] - d.key_ns), i, j) for j in range(lo, hi)
                       if sig_b[j] == sig_a[i]]
    used_a: set[int] = set()
    used_b: set[int] = set()
    pairs = []
    for _, i, j in sorted(candidates):
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            pairs.append((i, j))
    return sorted(pairs)


def _compare_topic(topic: str, recorded: Sequence[BagMessage], replayed: Sequence[BagMessage],
                   tolerances: Tolerances, from_ns: int | None = None,
                   alternative: Sequence[BagMessage] | None = None) -> TopicComparison:
    problems: list[str] = []
    types = sorted({m.msgtype for m in (*recorded, *replayed)})
    if len(types) > 1:
        problems.append(f'message types differ: {types}')
    rec = _decode(recorded, problems, 'recorded')
    rep = _decode(replayed, problems, 'replayed')
    stamps = [stamp_ns(msg) for _, msg in (*rec, *rep)]
    by_stamp = bool(stamps) and all(s is not None and s > 0 for s in stamps)

    def decoded(pairs):
        out = []
        for m, msg in pairs:
            kind, leaves = flatten(msg, m.msgtype)
            out.append(_Decoded(stamp_ns(msg) if by_stamp else m.timestamp_ns, kind, leaves))
        return sorted(out, key=lambda d: d.key_ns)

    a, b = decoded(rec), decoded(rep)
    skipped = 0
    if from_ns is not None:  # the start-up period is not compared (on either side)
        skipped = sum(d.key_ns < from_ns for d in a)
        a = [d for d in a if d.key_ns >= from_ns]
        b = [d for d in b if d.key_ns >= from_ns]
    nearest_s = tolerances.of(topic, 'match_window')
    window = nearest_s * 1e9 if nearest_s > 0 else _match_window([d.key_ns for d in a])
    inside = [d for d in b if a and a[0].key_ns - window <= d.key_ns <= a[-1].key_ns + window]
    outside = len(b) - len(inside) if a else 0
    b = inside if a else b
    kinds = sorted({d.kind for d in (*a, *b)})
    if len(kinds) > 1:
        problems.append(f'message kinds differ: {kinds}')
    sig_a, sig_b = [_signature(d) for d in a], [_signature(d) for d in b]
    alt = decoded(_decode(alternative or (), problems, 'alternative'))
    alt_keys = [d.key_ns for d in alt]

    def near(i: int, j: int) -> bool:
        return i < len(a) and j < len(b) and abs(b[j].key_ns - a[i].key_ns) <= window

    def alternatives(i: int) -> list[_Decoded]:
        # The other replay's messages of a[i]'s key and signature (by nearest time: the
        # nearest one of them).
        lo = bisect.bisect_left(alt_keys, a[i].key_ns - window)
        hi = bisect.bisect_right(alt_keys, a[i].key_ns + window)
        same = [d for d in alt[lo:hi] if _signature(d) == sig_a[i]]
        if nearest_s > 0 and same:
            return [min(same, key=lambda d: abs(d.key_ns - a[i].key_ns))]
        return same

    worst: dict[str, tuple[str, float, int]] = {}  # group -> (quantity, diff, key)
    counts = {'matched': 0, 'by_alternative': 0, 'out_of_tolerance': 0}

    def pair(i: int, j: int) -> None:
        diffs = _differences(a[i], b[j])
        if alternative is not None and _badness(diffs, topic, tolerances) > 1.0:
            first = diffs
            for other in alternatives(i):
                again = _differences(a[i], other)
                if _badness(again, topic, tolerances) < _badness(diffs, topic, tolerances):
                    diffs = again
            if _badness(diffs, topic, tolerances) > 1.0:  # left unmatched (counted)
                counts['out_of_tolerance'] += 1
                return
            counts['by_alternative'] += diffs is not first
        for group, (quantity, diff) in diffs.items():
            if group not in worst or diff > worst[group][1]:
                worst[group] = (quantity, diff, a[i].key_ns)
        counts['matched'] += 1

    if nearest_s > 0:
        for i, j in _nearest_pairs(a, b, sig_a, sig_b, window):
            pair(i, j)
    i = j = 0
    while nearest_s <= 0 and i < len(a) and j < len(b):
        gap = b[j].key_ns - a[i].key_ns
        if abs(gap) <= window:
            if sig_a[i] != sig_b[j]:  # e.g. one link's status lost: pair the others by name
                if near(i + 1, j) and sig_a[i + 1] == sig_b[j]:
                    i += 1
                    continue
                if near(i, j + 1) and sig_a[i] == sig_b[j + 1]:
                    j += 1
                    continue
            pair(i, j)
            i += 1
            j += 1
        elif gap < 0:
            j += 1
        else:
            i += 1
    matched, by_alternative, out_of_tolerance = (
        counts['matched'], counts['by_alternative'], counts['out_of_tolerance'])
    differences = tuple(
        FieldDifference(group, quantity, diff, tolerances.of(topic, quantity), key)
        for group, (quantity, diff, key) in sorted(worst.items()))
    return TopicComparison(topic, types[0] if types else '', 'stamp' if by_stamp else 'time',
                           len(a), len(b) + outside, matched,
                           tolerances.of(topic, 'unmatched'), outside, differences,
                           tuple(problems), skipped, by_alternative, out_of_tolerance)


def compare(recorded: Iterable[BagMessage], replayed: Iterable[BagMessage],
            tolerances: Tolerances = DEFAULT_TOLERANCES,
            topics: Iterable[str] | None = None, from_ns: Mapping[str, int] | None = None,
            neighbours: Iterable[str] = (),
            alternative: Iterable[BagMessage] = ()) -> Report:
    """Compare recorded with replayed messages, topic by topic.

    Parameters
    ----------
    recorded, replayed : iterable of BagMessage
        ``(topic, msgtype, time [ns], CDR bytes)``: from a bag (`inflarm_hw.bag.read_messages`)
        and from a replay (`inflarm_bringup.bag_regression.Replay.outputs`).
    tolerances : Tolerances
        Per quantity and topic; `DEFAULT_TOLERANCES` when not given.
    topics : iterable of str, optional
        The topics to compare; default: those on both sides. A topic on one side only is
        compared too when named here (and fails: nothing matches).
    from_ns : mapping of str to int, optional
        Topic -> the start of its comparison [ns] (stamp or time, the topic's match key):
        messages before it on either side are start-up, not compared (counted as
        ``skipped``).
    neighbours : iterable of str
        Topics (the outputs of timers) whose recorded message, out of tolerance against the
        replayed one, may match the ``alternative`` message of the same key and names
        instead: a timer can see an input taken in at about the moment it fired either
        before or after it (module docstring).
    alternative : iterable of BagMessage
        The other replay's outputs (inputs ambiguous against a firing in the other order).

    Returns
    -------
    Report
        ``report.passed``, the failures in words, and the table (text, markdown, CSV).
    """
    by_topic: dict[str, tuple[list[BagMessage], list[BagMessage]]] = {}
    for side, messages in ((0, recorded), (1, replayed)):
        for m in messages:
            by_topic.setdefault(m.topic, ([], []))[side].append(m)
    others: dict[str, list[BagMessage]] = {}
    for m in alternative:
        others.setdefault(m.topic, []).append(m)
    if topics is None:
        names = sorted(t for t, (a, b) in by_topic.items() if a and b)
        not_compared = tuple(sorted(t for t, (a, b) in by_topic.items() if b and not a))
    else:
        names = sorted({normalize_topic(t) for t in topics})
        not_compared = ()
    starts = {normalize_topic(t): v for t, v in (from_ns or {}).items()}
    near = {normalize_topic(t) for t in neighbours}
    return Report(tuple(_compare_topic(t, *by_topic.get(t, ([], [])), tolerances,
                                       starts.get(t), others.get(t, []) if t in near else None)
                        for t in names), not_compared)
