"""Recorded against replayed messages, topic by topic: counts, matches, per-field differences.

The pure half of the bag regression (``inflarm_bringup.bag_regression``): no rclpy. Messages
are `inflarm_hw.bag.BagMessage` tuples, decoded on both sides by the ``rosbags`` typestore.

Matching. Messages with a header stamp on both sides are matched by stamp, the others by time
(each side's ``timestamp_ns``: the bag regression gives both the time of the callback that
published them, `inflarm_bringup.ros.lockstep.published_at`), among those of the same label
(the kind and the text fields: a link's name, joint names, frames), so that a status the
recorder lost does not shift the next link's onto it. Both sides are sorted by that key
(stably) and merged: two messages match when their keys differ by at most half the median
spacing of the replay's distinct keys (else of the recorded keys; any amount with fewer than
two), so that a stream at a fixed rate never pairs a message with its neighbour. Replayed
messages more than that outside the compared recorded span (``outside``) are not counted: a
recorder sees a topic only while it is subscribed, the replay runs over the whole bag.
Recorded messages before a topic's start (``starts``) are not compared; the replayed ones
before it are outside.

Fields. A message's leaves (`flatten`) are grouped by field; a group has a quantity
(`QUANTITIES`) or must be equal. A leaf on one side only, a ``null`` against a number or
unequal text differs by inf. Tolerances (`Tolerances`) are absolute, in SI units, per quantity
and optionally per topic, over every matched message; ``unmatched`` is the share of a topic's
messages (of the larger count) that may be left unmatched.
"""

from collections.abc import Iterable, Mapping, Sequence
import csv
from dataclasses import dataclass, field, fields, is_dataclass
import io
import json
import math

import numpy as np

from inflarm_hw.bag import BagMessage, deserialize, normalize_topic

__all__ = ['DEFAULT_TOLERANCES', 'QUANTITIES', 'UNITS', 'FieldDifference', 'Report',
           'TopicComparison', 'Tolerances', 'compare', 'flatten', 'stamp_ns']

# Messages whose x/y/z(/w) are one field group (a point, a force), not three.
VECTOR_TYPES = frozenset({'geometry_msgs/msg/Point', 'geometry_msgs/msg/Point32',
                          'geometry_msgs/msg/Vector3', 'geometry_msgs/msg/Quaternion'})
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
    ('PressureCommand', 'chambers'): 'pressure', ('ChamberPressures', 'chambers'): 'pressure',
    ('TrialReport', 'rmse'): 'position', ('TrialReport', 'reach_time'): 'time',
    ('LinkStatus', 'pressure'): 'pressure', ('LinkStatus', 'wrinkling_moment'): 'torque',
    ('LinkStatus', 'moment'): 'torque',
    ('LinkStatus', 'margin'): 'torque',  # wrinkling_moment - moment [N m]
}
#: Unit of each quantity, for the report.
UNITS: Mapping[str, str] = {
    'position': 'm|rad', 'velocity': 'm/s|rad/s', 'force': 'N', 'torque': 'N m',
    'pressure': 'Pa', 'time': 's', 'exact': '', 'unmatched': 'share',
}


@dataclass(frozen=True)
class Tolerances:
    """Absolute tolerances [SI]: ``values`` maps ``'<quantity>'`` (`UNITS`) or
    ``'<topic>:<quantity>'`` (fully qualified topic, overriding it there) to one."""

    values: Mapping[str, float]

    def __post_init__(self) -> None:
        for key, value in self.values.items():
            quantity = key.rpartition(':')[2]
            if quantity not in UNITS:
                raise ValueError(f'tolerance {key!r}: unknown quantity {quantity!r}, expected '
                                 f'one of {sorted(UNITS)}')
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0
                    and (quantity != 'unmatched' or value <= 1.0)):
                raise ValueError(f'tolerance {key!r}: expected a finite number >= 0 (a share '
                                 f'<= 1 for unmatched), got {value!r}')

    def of(self, topic: str, quantity: str) -> float:
        """The tolerance of ``quantity`` on ``topic`` (the topic's own, else the quantity's)."""
        return 0.0 if quantity == 'exact' else float(
            self.values.get(f'{topic}:{quantity}', self.values.get(quantity, 0.0)))

    def updated(self, specs: Iterable[str]) -> 'Tolerances':
        """These tolerances with ``specs`` (``'[TOPIC:]QUANTITY=VALUE'``) applied.

        Raises
        ------
        ValueError
            On a malformed spec, an unknown quantity or a value that is not a number >= 0.
        """
        values = dict(self.values)
        for spec in specs:
            key, _, text = spec.partition('=')
            topic, colon, quantity = key.strip().rpartition(':')
            try:  # the quantity and the value are checked by Tolerances
                values[f'{normalize_topic(topic)}:{quantity}' if colon else quantity] = float(text)
            except ValueError:
                raise ValueError(f'tolerance {spec!r}: expected [TOPIC:]QUANTITY=VALUE, e.g. '
                                 "'force=0.01' or 'estimated_wrench:force=0.1'") from None
        return Tolerances(values)


#: The defaults: absolute tolerances per quantity, above the rounding by which a replay on
#: another machine may differ (on the one that recorded it, none) and far below what a changed
#: parameter moves (``inflarm_bringup/README.md``). ``unmatched`` allows for samples a
#: best-effort recorder lost: a changed node fails its fields instead.
DEFAULT_TOLERANCES = Tolerances({
    'position': 1e-4, 'velocity': 1e-3, 'force': 1e-3, 'torque': 1e-3, 'pressure': 100.0,
    'time': 0.25, 'unmatched': 0.05,
})


@dataclass(frozen=True)
class FieldDifference:
    """The largest difference of one field group over the matched messages of a topic."""

    group: str  # 'wrench.force'
    quantity: str  # of UNITS
    max_abs_diff: float  # [SI]; inf: a value on one side only, or unequal text
    tolerance: float
    worst_key_ns: int  # the match key (stamp or time [ns]) of the recorded message where largest

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

    @property
    def unmatched_share(self) -> float:
        total = max(self.recorded, self.replayed - self.outside)
        return 0.0 if total == 0 else 1.0 - self.matched / total

    @property
    def passed(self) -> bool:
        return not self.failures()

    def failures(self) -> list[str]:
        """What is out of tolerance, in words."""
        out = list(self.problems)
        if self.matched == 0 and (self.recorded or self.replayed):
            out.append(f'no message matched ({self.recorded} recorded, {self.replayed} replayed)')
        elif self.unmatched_share > self.unmatched_tolerance:
            out.append(f'{self.unmatched_share:.1%} of the messages unmatched (tolerance '
                       f'{self.unmatched_tolerance:.1%}): {self.recorded} recorded, '
                       f'{self.replayed - self.outside} replayed in their span, '
                       f'{self.matched} matched')
        for f in self.fields:
            if not f.passed:
                unit = ' ' + UNITS[f.quantity] if UNITS[f.quantity] else ''
                out.append(f'{f.group} differs by {f.max_abs_diff:.4g}{unit} (tolerance '
                           f'{f.tolerance:g}) at {f.worst_key_ns * 1e-9:.6f} s')
        return out


_HEADER = ('topic', 'key', 'recorded', 'replayed', 'outside', 'matched', 'field', 'max |diff|',
           'tolerance', 'ok')
_CSV = ('topic', 'type', 'key', 'recorded', 'replayed', 'outside', 'matched', 'field',
        'quantity', 'unit', 'max_abs_diff', 'tolerance', 'ok')


@dataclass(frozen=True)
class Report:
    """Every compared topic; ``passed`` when each is within its tolerances."""

    topics: tuple[TopicComparison, ...]
    not_compared: tuple[str, ...] = field(default=())  # topics replayed but not recorded

    @property
    def passed(self) -> bool:
        return bool(self.topics) and all(t.passed for t in self.topics)

    def rows(self) -> list[dict[str, object]]:
        """One row per topic and field group (a topic without fields: one row), `_CSV`'s keys."""
        return [dict(zip(_CSV, (
            t.topic, t.msgtype, t.key, t.recorded, t.replayed, t.outside, t.matched,
            *(('',) * 5 + (t.passed,) if f is None else (
                f.group, f.quantity, UNITS[f.quantity], f.max_abs_diff, f.tolerance, f.passed))),
            strict=True)) for t in self.topics for f in t.fields or (None,)]

    def table(self) -> str:
        """The report as a fixed-width text table, then the failures."""
        lines = [_HEADER, *self._cells()]
        widths = [max(len(line[i]) for line in lines) for i in range(len(_HEADER))]
        lines.insert(1, ['-' * w for w in widths])
        # The topic, key and field columns to the left, the numbers to the right.
        return '\n'.join(['  '.join(c.ljust(w) if i in (0, 1, 6) else c.rjust(w)
                                    for i, (c, w) in enumerate(zip(line, widths, strict=True))
                                    ).rstrip() for line in lines] + self._summary())

    def csv(self) -> str:
        """The report's rows as CSV (max_abs_diff and tolerance in the unit column's unit)."""
        out = io.StringIO()
        writer = csv.DictWriter(out, fieldnames=_CSV)
        writer.writeheader()
        writer.writerows({k: repr(v) if isinstance(v, float) else v for k, v in row.items()}
                         for row in self.rows())
        return out.getvalue()

    def _cells(self) -> list[list[str]]:
        return [[f'{c:.3g}' if isinstance(c, float) else str(c) for c in (
            r['topic'], r['key'], r['recorded'], r['replayed'], r['outside'], r['matched'],
            f"{r['field']} [{r['unit']}]" if r['field'] and r['unit'] else r['field'],
            r['max_abs_diff'], r['tolerance'], 'ok' if r['ok'] else 'FAIL')] for r in self.rows()]

    def _summary(self) -> list[str]:
        lines = [f'FAIL {t.topic}: {failure}' for t in self.topics for failure in t.failures()]
        if self.not_compared:
            lines.append(f"not compared (not in the bag): {', '.join(self.not_compared)}")
        if self.passed:
            lines.append(f'PASS: {len(self.topics)} topics within tolerance')
        elif not self.topics:
            lines.append('FAIL: no topic to compare')
        else:
            failed = ', '.join(t.topic for t in self.topics if not t.passed)
            lines.append(f'FAIL: {failed} out of tolerance')
        return lines


# -- flattening ----------------------------------------------------------------------------------

Leaf = float | int | bool | str | None


def flatten(message: object, msgtype: str) -> tuple[str, dict[str, tuple[str, Leaf]]]:
    """A decoded message (`inflarm_hw.bag.deserialize`) of ROS type ``msgtype`` as ``(kind,
    {leaf path: (field group, value)})``, e.g. ``'wrench.force.x': ('wrench.force', 0.1)``.

    The kind is ``msgtype``, or the ``type`` of an inflarm JSON message carried in a
    ``std_msgs/String`` (leaves: its JSON fields, ``'chambers.B1'``). The header stamp (the
    match key) is left out.
    """
    leaves: dict[str, tuple[str, Leaf]] = {}
    if msgtype == 'std_msgs/msg/String':
        try:
            body = json.loads(message.data)
        except ValueError:
            body = None
        if isinstance(body, dict) and isinstance(body.get('type'), str):
            for key, value in body.items():
                if key not in ('type', 'schema_version'):  # the kind says which type it is
                    _flatten(value, key, key, leaves)
            return body['type'], leaves
    _flatten(message, '', None, leaves)
    for part in ('sec', 'nanosec'):  # the match key
        leaves.pop(f'header.stamp.{part}', None)
    return msgtype, leaves


def _flatten(value: object, path: str, group: str | None,
             leaves: dict[str, tuple[str, Leaf]]) -> None:
    # A leaf's group: the top-level JSON field, else the nearest array or vector around it,
    # else the leaf itself.
    if is_dataclass(value):  # a rosbags message (whose __msgtype__ is no field)
        if group is None and path and getattr(value, '__msgtype__', '') in VECTOR_TYPES:
            group = path
        value = {f.name: getattr(value, f.name) for f in fields(value)
                 if not f.name.startswith('__')}
    if isinstance(value, dict):
        for key, item in value.items():
            _flatten(item, f'{path}.{key}' if path else key, group, leaves)
    elif isinstance(value, (np.ndarray, list, tuple)):
        for i, item in enumerate(value.tolist() if isinstance(value, np.ndarray) else value):
            _flatten(item, f'{path}[{i}]', group or path, leaves)
    else:
        leaves[path] = (group or path, value.item() if isinstance(value, np.generic) else value)


def _difference(a: Leaf, b: Leaf) -> float:
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b)):
        return 0.0 if a == b else math.inf
    d = abs(float(a) - float(b))
    return 0.0 if math.isnan(a) and math.isnan(b) else (math.inf if math.isnan(d) else d)


# -- matching ------------------------------------------------------------------------------------

def stamp_ns(message: object) -> int | None:
    """The header stamp [ns] of a decoded message, or None when it has no header."""
    stamp = getattr(getattr(message, 'header', None), 'stamp', None)
    return None if stamp is None else stamp.sec * 10**9 + stamp.nanosec


def _label(decoded: tuple) -> tuple:
    # What names a message among a callback's several: its kind and its text leaves that are
    # no quantity (a link's name, joint names, frames).
    _, kind, leaves = decoded
    return kind, tuple(sorted((path, value) for path, (group, value) in leaves.items()
                              if isinstance(value, str) and (kind, group) not in QUANTITIES))


def _compare_topic(topic: str, recorded: Sequence[BagMessage], replayed: Sequence[BagMessage],
                   tolerances: Tolerances, start_ns: int | None = None) -> TopicComparison:
    problems: list[str] = []
    types = sorted({m.msgtype for m in (*recorded, *replayed)})
    if len(types) > 1:
        problems.append(f'message types differ: {types}')
    rec: list[tuple[BagMessage, object]] = []
    rep: list[tuple[BagMessage, object]] = []
    for side, messages, out in (('recorded', recorded, rec), ('replayed', replayed, rep)):
        for m in messages:
            try:
                out.append((m, deserialize(m.data, m.msgtype)))
            except ValueError as err:
                problems.append(f'{side} message at {m.timestamp_ns * 1e-9:.6f} s: {err}')
    stamps = [stamp_ns(msg) for _, msg in (*rec, *rep)]
    by_stamp = bool(stamps) and all(s is not None and s > 0 for s in stamps)
    # (key [ns], kind, leaves) by key, from the start on; sorted() is stable, so messages of
    # one key keep the order they were recorded or published in.
    a, b = (sorted(((stamp_ns(msg) if by_stamp else m.timestamp_ns, *flatten(msg, m.msgtype))
                    for m, msg in side), key=lambda d: d[0]) for side in (rec, rep))
    if start_ns is not None:
        a = [d for d in a if d[0] >= start_ns]  # the replayed ones before: outside
    # The replay publishes a callback's messages at its one time, the recorder takes them in
    # spread out: the spacing of the replay's distinct keys is the rate's.
    keys = np.unique([d[0] for d in b]) if len({d[0] for d in b}) > 1 else np.unique(
        [d[0] for d in a])
    window = max(float(np.median(np.diff(keys))) / 2.0, 1.0) if len(keys) > 1 else math.inf
    inside = [d for d in b if not a or a[0][0] - window <= d[0] <= a[-1][0] + window]
    outside, b = len(b) - len(inside), inside
    kinds = sorted({d[1] for d in (*a, *b)})
    if len(kinds) > 1:
        problems.append(f'message kinds differ: {kinds}')
    worst: dict[str, tuple[str, float, int]] = {}  # group -> (quantity, diff, key)
    matched = 0
    # Merged per label: a message the recorder lost from a callback's several (a status per
    # link) leaves the others paired with their own.
    by_label: dict[tuple, tuple[list, list]] = {}
    for side, decoded in ((0, a), (1, b)):
        for d in decoded:
            by_label.setdefault(_label(d), ([], []))[side].append(d)
    for a_, b_ in by_label.values():
        i = j = 0
        while i < len(a_) and j < len(b_):
            gap = b_[j][0] - a_[i][0]
            if gap < -window:
                j += 1
            elif gap > window:
                i += 1
            else:
                (key, kind, left), right = a_[i], b_[j][2]
                for path in left.keys() | right.keys():
                    group = (left.get(path) or right[path])[0]
                    x = left.get(path, (group, _MISSING))[1]
                    y = right.get(path, (group, _MISSING))[1]
                    diff = math.inf if _MISSING in (x, y) else _difference(x, y)
                    if group not in worst or diff > worst[group][1]:
                        worst[group] = (QUANTITIES.get((kind, group), 'exact'), diff, key)
                matched, i, j = matched + 1, i + 1, j + 1
    differences = tuple(
        FieldDifference(group, quantity, diff, tolerances.of(topic, quantity), key)
        for group, (quantity, diff, key) in sorted(worst.items()))
    return TopicComparison(topic, types[0] if types else '', 'stamp' if by_stamp else 'time',
                           len(a), len(b) + outside, matched, tolerances.of(topic, 'unmatched'),
                           outside, differences, tuple(problems))


def compare(recorded: Iterable[BagMessage], replayed: Iterable[BagMessage],
            tolerances: Tolerances = DEFAULT_TOLERANCES, topics: Sequence[str] | None = None,
            starts: Mapping[str, int] | None = None) -> Report:
    """Compare recorded with replayed messages, topic by topic (module docstring).

    Parameters
    ----------
    recorded, replayed : iterable of BagMessage
        From a bag (`inflarm_hw.bag.read_messages`) and a replay (``Replay.outputs``).
    tolerances : Tolerances
    topics : sequence of str, optional
        The topics to compare (one on one side only fails); default: those on both sides.
    starts : mapping of str to int, optional
        Topic -> the start of its comparison [ns] (in its match key: stamp or time).
    """
    by_topic: dict[str, tuple[list[BagMessage], list[BagMessage]]] = {}
    for side, messages in ((0, recorded), (1, replayed)):
        for m in messages:
            by_topic.setdefault(m.topic, ([], []))[side].append(m)
    if topics is None:
        names = sorted(t for t, (a, b) in by_topic.items() if a and b)
        not_compared = tuple(sorted(t for t, (a, b) in by_topic.items() if b and not a))
    else:
        names, not_compared = sorted({normalize_topic(t) for t in topics}), ()
    start = {normalize_topic(t): v for t, v in (starts or {}).items()}
    return Report(tuple(_compare_topic(t, *by_topic.get(t, ([], [])), tolerances, start.get(t))
                        for t in names), not_compared)
