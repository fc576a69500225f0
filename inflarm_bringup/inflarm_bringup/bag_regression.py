"""``inflarm-bag-regression``: replay a bag's inputs into the estimation and control nodes and
compare their outputs with the recorded ones.

Usage::

    inflarm-bag-regression BAG [--nodes load_estimator,elastostatic_ik,pressure_controller]
                               [--params-file F ...] [--out DIR] [--tolerance SPEC ...]

    # e.g. a run recorded with bag_recorder, the controller's trials 5 s long in that run:
    inflarm-bag-regression run1 --params-file my_params.yaml --tolerance pressure=50

BAG is a rosbag2 directory (sqlite3 or MCAP) recorded from a running system, holding the
inputs of the nodes under test and their outputs. Exit status: 0 when every compared topic is
within tolerance, 1 when one is not, 2 on bad arguments, an unreadable bag, a bag without the
topics a node needs, or a node that cannot be built from its parameters.

Nodes under test (`NODES`): ``load_estimator``, ``elastostatic_ik``, ``pressure_controller``, the
classes as they are, each with the parameter files the system gives it (``inflatable_arm.yaml``,
its installed ``config/<node>.yaml``, ``soft_arm.yaml`` for the controller:
``inflarm_bringup.systems``) and then ``--params-file`` (files keyed by node name or ``/**``;
pass what the recorded run was started with). Each node's input and output topics are read off
the node after construction (its subscriptions and publishers). Without ``--nodes``, a node
runs when the bag holds one of its inputs (or another node under test publishes one) and one of
its outputs, or when it feeds such a node an input the bag lacks. An output of a node under
test that another one subscribes to comes from the replay, not from the bag (e.g.
``estimated_wrench`` into ``elastostatic_ik``); the recorded copy is only compared.

Replay (`replay`), in this process and deterministic: the nodes run in a private rclpy context
with DDS discovery off, with ``use_sim_time``, and are never spun. The bag's inputs are handed,
in record-time order, straight to the callbacks of the nodes' own subscriptions, as messages
rclpy deserializes from the recorded CDR; before each, the nodes' clocks are set to its record
time (a ``rosgraph_msgs/Clock`` on their own ``/clock`` subscriptions), so their stamps,
freshness checks and timeouts see the recorded time. Each timer's callback is called when the
simulated time reaches its due time, before any input recorded at or after it. What a node
publishes is captured (canonical CDR, stamped with the simulated time) and handed to the nodes
under test that subscribe to it before time moves on. So each input is consumed, each timer
due has fired and each output has been delivered before the next event: two replays give the
same bytes.

Why hand messages to the callbacks instead of sending them over DDS: a DDS replay in lock step
needs a barrier on every message into and out of every node (best-effort topics may drop them
under load, a depth-1 command topic overwrites them, and an rclpy executor orders ready
timers and subscriptions by its own rules), and the nodes' outputs would reach any system
running on the same domain. Direct delivery gives one order, the bag's, with the same node
code, the same message classes and the same callbacks (guarded: a bad recorded input is
rejected with a warning, as in the running node). What it leaves out is DDS itself: QoS
matching and queue depths.

Timers follow the recording: a node's timer is found by its recorded output that is periodic
at the timer's period (`timer_phase`), e.g. ``chamber_pressure_command`` for the controller's
5 Hz step, and it fires at every recorded firing of that output (`firings_of`): at each
distinct header stamp when the node stamps it with its clock (``motor_position_command``:
each stamp IS a firing time, so a delayed firing and the catch-up after it both count), else
just before each group of record times (one firing's messages, within a tenth of a period).
Only where the node published nothing (before its first output, after its last, across a
gap of more than 1.5 periods) does it fire on a grid of its period; a timer without such an
output fires every period from one period after the bag's first message.

Inputs follow the node's own lag: where a node's recorded outputs carry an input's stamp (the
load estimator's estimates carry their joint_states sample's), the input reaches the node just
before the first such output was recorded (never before its own record time: `retime_inputs`).
Such an input whose output was recorded less than ``RECORD_ORDER_NS`` (1 ms) before one of the
node's record-time firings is ambiguous: a recorder takes in messages of different topics
in its own order, and the firing may have come first (either order occurs: the README has the
counts). The replay (``order='after'``) puts it after the firing; ``order='before'`` puts
every ambiguous input before its firing; the command runs both and a recorded timer output
matches when within tolerance of either. Unstamped inputs (``control_task``) go at their
record time, and in the ``order='before'`` replay to the other side of a due time of their
node's timers less than ``UNSTAMPED_ORDER_NS`` (2 ms) from it: there is nothing to tell their
order by. Such a firing is on the grid worked back from the node's first output, so its due
time is itself uncertain by the timer's jitter (a few ms on a loaded machine); the window does
not cover that.

Start-up: the first ``--skip-start-s`` (default 1.0 s) after each node's first recorded output
is not compared (as ``ros2 bag play --start-offset`` skips): a node's first outputs lag
behind their inputs, and the recorder's first copies of a topic lag behind what the node
published after them (the README has the figures). It counts from each node's first output,
not from the bag's first message, because the nodes start publishing well into a recording.

Ordering ambiguity that stays: a replayed message of a timer output out of tolerance in both
orders is counted as unmatched, and a topic passes with up to 5 % unmatched (``unmatched``),
so that one event taken in on the other side of a firing does not fail a run while a changed
node (out of tolerance on most messages) does. ``trial_report``'s RMSE has a tolerance of
1 mm: one of the trial's steps on the neighbouring 20 Hz ball sample
(``bag_compare.DEFAULT_TOLERANCES``). Two more come from the same ordering:

- ``motor_position_command``: ``elastostatic_ik`` plans a whole tip trajectory from one load
  estimate, the latest when the path arrives; which one is latest is a sub-millisecond
  ordering the record cannot fix, and one estimate's sample-to-sample noise moves every
  command of the path. Its joint positions have a tolerance of 1e-3 rad (0.6 mm at the tip
  of a 0.6 m link), above that noise and below what a 10 % stiffer IK model moves them by
  (the README has both figures; the tests check that the stiffer model fails).
- ``link_status``: the estimator's 10 Hz firing publishes only when a new estimate arrived
  since the last one, so whether a firing publishes is that ordering too. Its messages are
  matched to the nearest recorded one of the same link within one period (0.1 s), the matched
  values compared, and up to 15 % may be unmatched (a count difference); a changed estimator
  stiffness leaves almost none within tolerance.

Comparison (``inflarm_bringup.bag_compare``): per output topic recorded in the bag, counts,
messages matched by header stamp or by time, the largest difference per field against
tolerances per quantity (positions [m/rad], forces [N], pressures [Pa], ...), optionally per
topic (``--tolerance [TOPIC:]QUANTITY=VALUE``, repeatable). ``diagnostics`` is not compared
(its counts depend on when its reports fell in the recording). ``--out DIR`` writes the
replayed outputs as a bag (``DIR/replayed``) and the report (``DIR/report.md``,
``DIR/report.csv``).
"""

import argparse
import bisect
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import os
import pathlib
import sys

import numpy as np

from inflarm_bringup.bag_compare import (
    DEFAULT_TOLERANCES,
    UNITS,
    Report,
    Tolerances,
    compare,
    stamp_ns,
)
from inflarm_bringup.node_io import NodeIo
from inflarm_hw.bag import BagMessage, BagWriter, bag_info, deserialize, read_messages
from inflarm_msgs_json.cli import run_command

__all__ = [
    'NODES',
    'SKIP_START_S',
    'UNSTAMPED_ORDER_NS',
    'Replay',
    'TimerSchedule',
    'compare',
    'default_params_files',
    'firings_of',
    'main',
    'regression',
    'replay',
    'retime_inputs',
    'select_nodes',
    'start_times',
    'timer_due_times',
    'timer_phase',
]

PROG = 'inflarm-bag-regression'
#: Node name -> its class, as ``'module:Class'``.
NODES: Mapping[str, str] = {
    'load_estimator': 'inflarm_estimation.nodes.load_estimator:LoadEstimator',
    'elastostatic_ik': 'inflarm_control.nodes.elastostatic_ik:ElastostaticIk',
    'pressure_controller': 'inflarm_control.nodes.pressure_controller:PressureController',
}
#: An input due at a node less than this before one of its timer firings aligned to record
#: times [ns] goes to it after the firing: a recorder takes in the messages of different
#: topics that are ready together in its own order (the README has the offsets measured).
RECORD_ORDER_NS = 1_000_000
#: An unstamped input (``control_task``) recorded less than this from a due time of a timer of
#: the node that takes it [ns] goes to the other side of that firing in the other-order replay
#: (``order='before'``): record-time order across topics is not reliable below it, and a
#: firing that published nothing is only on the grid worked back from the node's next output.
UNSTAMPED_ORDER_NS = 2_000_000
#: The start-up not compared by default [s]: from each node's first recorded output.
SKIP_START_S = 1.0
# Burst grouping and grid test of `timer_phase`.
_MIN_BURSTS = 3
_LATE = 0.4  # a burst is on the grid within this share of a period after the phase
_ON_GRID_SHARE = 0.8  # the share of bursts on the grid for a periodic topic


@dataclass(frozen=True)
class TimerSchedule:
    """When a node's timer fires in the replay: ``due_ns``, on the grid ``phase_ns + k
    period_ns`` or at the recorded output of ``aligned_to`` (None: the grid starts one period
    after the bag's first message), ``recorded_firings`` of them; ``by`` what the output's
    times are: ``'stamp'`` (its header stamps, the node's clock when it published) or
    ``'time'`` (its record times)."""

    node: str
    index: int
    period_ns: int
    phase_ns: int | None
    aligned_to: str | None
    due_ns: tuple[int, ...]
    recorded_firings: int
    by: str = 'time'


@dataclass(frozen=True)
class Replay:
    """A replay's outcome.

    Attributes
    ----------
    bag : pathlib.Path
    nodes : tuple of NodeIo
        The nodes under test.
    params_files : mapping of str to tuple of str
        Node name -> the parameter files it was built with, in order.
    inputs : mapping of str to int
        Bag topic -> messages delivered from the bag.
    timers : tuple of TimerSchedule
    outputs : tuple of BagMessage
        Everything the nodes published, in order, stamped with the simulated time [ns].
    start_ns, end_ns : int
        The simulated span (the bag's).
    timer_outputs : frozenset of str
        The output topics the nodes published from a timer callback.
    """

    bag: pathlib.Path
    nodes: tuple[NodeIo, ...]
    params_files: Mapping[str, tuple[str, ...]]
    inputs: Mapping[str, int]
    timers: tuple[TimerSchedule, ...]
    outputs: tuple[BagMessage, ...]
    start_ns: int
    end_ns: int
    timer_outputs: frozenset[str] = frozenset()

    @property
    def compared_topics(self) -> list[str]:
        """The outputs of the nodes under test that are compared (diagnostics are not)."""
        return sorted({t for io in self.nodes for t in io.compared_outputs})

    def outputs_on(self, topic: str) -> list[BagMessage]:
        return [m for m in self.outputs if m.topic == topic]


def default_params_files(name: str) -> list[str]:
    """The parameter files the simulated system starts node ``name`` with, in order."""
    from inflarm_bringup.systems import sim

    for node in sim():
        if node.executable == name:
            return node.parameter_files()
    raise ValueError(f'{name} is not a node of the simulated system')


def select_nodes(ios: Sequence[NodeIo], bag_topics: Mapping[str, str],
                 requested: bool = False) -> tuple[NodeIo, ...]:
    """The nodes a bag can test, in the order of ``ios``.

    A node is tested when the bag holds one of its compared outputs and one of its inputs (or
    another node of ``ios`` publishes one); a node is also run when it publishes an input of a
    tested node that the bag lacks. With ``requested``, every node of ``ios`` must qualify.

    Parameters
    ----------
    ios : sequence of NodeIo
        The candidates.
    bag_topics : mapping of str to str
        The bag's topics and their types.
    requested : bool
        The candidates were asked for by name: one that does not qualify is an error.

    Raises
    ------
    ValueError
        When no node qualifies, a requested one does not (naming what it lacks), or a topic's
        type in the bag differs from the node's.
    """
    def available(io: NodeIo) -> bool:
        return any(t in bag_topics or any(t in o.outputs for o in ios if o is not io)
                   for t in io.inputs)

    def needs(io: NodeIo) -> str:
        return (f'{io.name} needs one of its inputs {sorted(io.inputs)} and one of its outputs '
                f'{io.compared_outputs} in the bag')

    chosen = [io for io in ios if available(io)
              and any(t in bag_topics for t in io.compared_outputs)]
    while True:  # add the nodes that feed a chosen one an input the bag lacks
        missing = {t for io in chosen for t in io.inputs if t not in bag_topics}
        feeders = [io for io in ios if io not in chosen and available(io)
                   and missing & set(io.outputs)]
        if not feeders:
            break
        chosen += feeders
    chosen = [io for io in ios if io in chosen]
    held = f'the bag holds {sorted(bag_topics)}'
    if requested and len(chosen) < len(ios):
        raise ValueError('; '.join(needs(io) for io in ios if io not in chosen) + f'; {held}')
    if not chosen:
        raise ValueError('no node under test applies to this bag: '
                         + '; '.join(needs(io) for io in ios) + f'; {held}')
    produced = {t for io in chosen for t in io.outputs}
    for io in chosen:
        for topic, msgtype in io.inputs.items():
            if topic in bag_topics and topic not in produced and bag_topics[topic] != msgtype:
                raise ValueError(f'{topic} holds {bag_topics[topic]} in the bag, but '
                                 f'{io.name} subscribes to it as {msgtype}')
        for topic, msgtype in io.outputs.items():
            if topic in bag_topics and bag_topics[topic] != msgtype:
                raise ValueError(f'{topic} holds {bag_topics[topic]} in the bag, but '
                                 f'{io.name} publishes it as {msgtype}')
    return tuple(chosen)


def timer_phase(times_ns: Sequence[int], period_ns: int) -> int | None:
    """When a timer of ``period_ns`` that published at ``times_ns`` [ns] fired, or None when the
    times are not periodic at that period.

    Messages within half a period of a burst's first are one burst (one firing may publish
    several messages). Delays (callback, transport, recorder) only ever make a burst later
    than its firing, so the bursts of a timer gather just after its phase: they are periodic
    when at least 80 % of them lie within 40 % of a period after one of them (modulo the
    period), and the phase is the earliest such. Each burst is judged against that phase, not
    against its neighbours: one late firing on a loaded machine is one late burst, not two
    gaps off the grid, and a burst before the rest (a first message that came early) is left
    out rather than taken for the phase. Bursts at arbitrary times gather so within a 40 %
    window for about half of them at most.

    Returns
    -------
    int or None
        A time [ns] the timer was due at (it is due every ``period_ns`` from there).
    """
    starts = bursts(times_ns, period_ns)
    if len(starts) < _MIN_BURSTS:
        return None
    s = np.asarray(starts, dtype=np.int64)
    # residues sorted, and once more a period on (the window may wrap): the bursts within
    # the window after residue i are i .. end[i] - 1 of that list (n log n: long bags)
    residues = np.sort((s - s[0]) % period_ns)
    wrapped = np.concatenate([residues, residues + period_ns])
    end = np.searchsorted(wrapped, residues + _LATE * period_ns, side='right')
    gathered = end - np.arange(len(residues))
    if gathered.max() < _ON_GRID_SHARE * len(s):
        return None
    # of the residues that gather the most, the one the others come after
    best = np.nonzero(gathered == gathered.max())[0]
    spread = wrapped[end[best] - 1] - residues[best]
    return int(s[0] + residues[best[int(np.argmax(spread))]])


def bursts(times_ns: Sequence[int], period_ns: int) -> list[int]:
    """The first of each group of ``times_ns`` within half of ``period_ns`` of it, sorted."""
    if period_ns <= 0:
        raise ValueError(f'expected period_ns > 0, got {period_ns!r}')
    starts: list[int] = []
    for t in sorted(int(t) for t in times_ns):
        if not starts or t - starts[-1] >= period_ns // 2:
            starts.append(t)
    return starts


def firings_of(times_ns: Sequence[int], period_ns: int, by: str) -> list[int]:
    """The firings of a timer of ``period_ns`` that published at ``times_ns`` [ns], sorted.

    ``by='stamp'``: the times are header stamps of the node's clock when it published, so
    each distinct stamp is one firing (one firing may publish several messages with its
    stamp; a firing the machine delayed and the next one, on time, may be a few ms apart and
    both count). ``by='time'``: record times; the messages within a tenth of a period of a
    group's first are one firing.
    """
    if period_ns <= 0:
        raise ValueError(f'expected period_ns > 0, got {period_ns!r}')
    if by not in ('stamp', 'time'):
        raise ValueError(f"by: expected 'stamp' or 'time', got {by!r}")
    window = 1 if by == 'stamp' else max(period_ns // 10, 1)
    starts: list[int] = []
    for t in sorted(int(t) for t in times_ns):
        if not starts or t - starts[-1] >= window:
            starts.append(t)
    return starts


def timer_due_times(period_ns: int, firings_ns: Sequence[int], start_ns: int, end_ns: int,
                    offset_ns: int = -1) -> tuple[list[int], int]:
    """When a timer fires in a replay from ``start_ns`` to ``end_ns`` [ns].

    At every one of ``firings_ns`` (the timer's recorded firings, `firings_of`) plus
    ``offset_ns`` (-1: just before its record time; 0: at its stamp, the node's clock when
    it published); on a grid of ``period_ns`` only where the node published nothing: back
    from the first firing, on from the last, and across a gap of more than 1.5 periods (on
    from the firing before it). Without firings: every period from ``start_ns + period_ns``.

    Returns
    -------
    due : list of int
        Increasing due times [ns] within ``[start_ns, end_ns]``.
    recorded : int
        How many of them are recorded firings.
    """
    if period_ns <= 0:
        raise ValueError(f'expected period_ns > 0, got {period_ns!r}')
    fired = sorted({int(f) + offset_ns for f in firings_ns})
    if not fired:
        return list(range(start_ns + period_ns, end_ns + 1, period_ns)), 0
    due = list(range(fired[0] - period_ns * ((fired[0] - start_ns) // period_ns), fired[0],
                     period_ns))
    for f, after in zip(fired, [*fired[1:], None], strict=True):
        due.append(f)
        limit = end_ns + 1 if after is None else after - period_ns // 2
        if after is None or after - f > 3 * period_ns // 2:
            due += range(f + period_ns, limit, period_ns)
    due = [t for t in due if start_ns <= t <= end_ns]
    recorded = len(set(due) & set(fired))
    return due, recorded


def _schedules(io: NodeIo, recorded: Mapping[str, Sequence[tuple[int, int | None]]],
               start_ns: int, end_ns: int) -> list[TimerSchedule]:
    # recorded: output topic -> [(record time, header stamp or None)]. A stamped output is
    # tried by its stamps first: a node stamping with its clock gives the exact firing times.
    # The timer's output is the one periodic at its period (`timer_phase`); its every firing
    # is replayed as recorded (`timer_due_times`).
    schedules = []
    for index, period in enumerate(io.timer_periods_ns):
        phase = topic = None
        by, firings, offset = 'time', [], -1
        for candidate in sorted(io.outputs, key=lambda t: -len(recorded.get(t, ()))):
            pairs = recorded.get(candidate, ())
            ways = [('time', [t for t, _ in pairs], -1)]
            if pairs and all(s is not None for _, s in pairs):
                ways.insert(0, ('stamp', [s for _, s in pairs], 0))
            for way in ways:
                phase = timer_phase(way[1], period)
                if phase is not None:
                    topic, by, offset = candidate, way[0], way[2]
                    firings = firings_of(way[1], period, by)
                    break
            if topic is not None:
                break
        due, fired = timer_due_times(period, firings, start_ns, end_ns, offset)
        schedules.append(TimerSchedule(io.name, index, period, phase, topic, tuple(due),
                                       fired, by))
    return schedules


def _stamp_of(message: BagMessage) -> int | None:
    try:
        stamp = stamp_ns(deserialize(message.data, message.msgtype))
    except ValueError:
        return None
    return stamp if stamp else None


def retime_inputs(inputs: Sequence[BagMessage], subscribers: Mapping[str, Sequence[str]],
                  consumed: Mapping[tuple[str, str], Mapping[int, int]],
                  firings: Mapping[str, Sequence[int]] | None = None,
                  order: str = 'after') -> list[tuple[BagMessage, tuple[str, ...]]]:
    """When each recorded input reaches each node that subscribes to it.

    At its record time, except where the node's recorded outputs carry the input's stamp
    (``consumed[(node, topic)]``: stamp -> earliest record time of such an output): the node
    had taken the input in by then, so it gets it just before that (never before its record
    time, and in the topic's order). So a node that lagged behind its inputs in the recording
    (e.g. load_estimator on a loaded machine) lags alike in the replay, and its timers see the
    inputs it had seen. An input that would reach a node less than `RECORD_ORDER_NS` before
    one of ``firings[node]`` reaches it 1 ns after that firing instead. An unstamped input
    (no header) less than `UNSTAMPED_ORDER_NS` from the nearest of ``firings[node]`` goes to
    the other side of it with ``order='before'`` (at its record time otherwise).

    Parameters
    ----------
    inputs : sequence of BagMessage
        In record-time order.
    subscribers : mapping of str to sequence of str
        Topic -> the nodes under test that subscribe to it.
    consumed : mapping
        ``(node, topic)`` -> ``{stamp [ns]: record time [ns]}``.
    firings : mapping of str to sequence of int, optional
        Node -> increasing times [ns] its timers fire at, aligned to record times.
    order : {'after', 'before'}
        Where an input goes that is ambiguous, its node's output recorded less than
        `RECORD_ORDER_NS` from one of the node's firings: ``'after'`` (the default)
        that firing when recorded just before it, ``'before'`` it
        when recorded just before or just after it (the other order, `regression`); with
        ``'before'``, an unstamped input near a firing also goes to its other side.

    Returns
    -------
    list of (BagMessage, tuple of str)
        Messages (with their delivery times as ``timestamp_ns``) and the nodes they go to, in
        delivery order.
    """
    last: dict[tuple[str, str], int] = {}
    out: list[tuple[int, int, BagMessage, tuple[str, ...]]] = []
    for seq, m in enumerate(inputs):
        by_time: dict[int, list[str]] = {}
        for node in subscribers.get(m.topic, ()):
            when = m.timestamp_ns
            done = consumed.get((node, m.topic))
            stamp = _stamp_of(m) if done else None
            fired = (firings or {}).get(node, ())
            if stamp is not None and stamp in done:
                when = max(when, done[stamp] - 1)
                # Both are outputs of the node, recorded in the recorder's order.
                k = bisect.bisect_left(fired, when)
                if order == 'after' and k < len(fired) and fired[k] - when < RECORD_ORDER_NS:
                    when = fired[k] + 1
                elif order == 'before' and k > 0 and when - fired[k - 1] < RECORD_ORDER_NS:
                    when = fired[k - 1] - 1
            elif order == 'before' and fired and _stamp_of(m) is None:
                # Unstamped: at its record time, or in the other replay on the other side of a
                # due time within UNSTAMPED_ORDER_NS (the nearest one).
                k = bisect.bisect_left(fired, when)
                ahead = fired[k] - when if k < len(fired) else None
                behind = when - fired[k - 1] if k > 0 else None
                if ahead is not None and ahead < UNSTAMPED_ORDER_NS and (
                        behind is None or ahead <= behind):
                    when = fired[k] + 1
                elif behind is not None and behind < UNSTAMPED_ORDER_NS:
                    when = fired[k - 1] - 1
            when = max(when, last.get((node, m.topic), when))
            last[(node, m.topic)] = when
            by_time.setdefault(when, []).append(node)
        for when, nodes in by_time.items():
            out.append((when, seq, m._replace(timestamp_ns=when), tuple(nodes)))
    out.sort(key=lambda item: (item[0], item[1]))
    return [(m, nodes) for _, _, m, nodes in out]


def _consumed(chosen: Sequence[NodeIo], inputs: Sequence[BagMessage],
              recorded: Mapping[str, Sequence[tuple[int, int | None]]]
              ) -> dict[tuple[str, str], dict[int, int]]:
    # (node, input topic) -> {stamp: earliest record time of an output of that node with it},
    # for the input topics most of whose stamps reappear on an output of the node.
    stamps: dict[str, set[int]] = {}
    for m in inputs:
        stamp = _stamp_of(m)
        if stamp is not None:
            stamps.setdefault(m.topic, set()).add(stamp)
    consumed = {}
    for io in chosen:
        for topic in io.inputs:
            done: dict[int, int] = {}
            for output in io.outputs:
                pairs = [(s, t) for t, s in recorded.get(output, ()) if s is not None]
                if stamps.get(topic) and 2 * sum(s in stamps[topic] for s, _ in pairs) >= len(
                        stamps[topic]):
                    for s, t in pairs:
                        done[s] = min(t, done.get(s, t))
            if done:
                consumed[(io.name, topic)] = done
    return consumed


def replay(bag: str | os.PathLike, nodes: Sequence[str] | None = None,
           params_files: Sequence[str | os.PathLike] = (), order: str = 'after') -> Replay:
    """Replay the inputs of ``bag`` into the nodes under test, in lock step (module docstring).

    Parameters
    ----------
    bag : path-like
        A rosbag2 directory.
    nodes : sequence of str, optional
        Names from `NODES`; default: those the bag's topics apply to (`select_nodes`).
    params_files : sequence of path-like
        Parameter files for every node, after the system's files.
    order : {'after', 'before'}
        Where an input ambiguous against a timer firing goes (`retime_inputs`).

    Returns
    -------
    Replay

    Raises
    ------
    ValueError
        On an unreadable bag, an unknown node, a missing parameter file, a bag without the
        topics a node needs, or a node that cannot be built from its parameters.
    """
    if order not in ('after', 'before'):
        raise ValueError(f"order: expected 'after' or 'before', got {order!r}")
    info = bag_info(bag)
    files = [str(f) for f in params_files]
    for f in files:
        if not os.path.isfile(f):
            raise ValueError(f'parameter file {f!r} does not exist')
    names = list(NODES) if nodes is None else list(dict.fromkeys(nodes))
    unknown = [n for n in names if n not in NODES]
    if unknown or not names:
        raise ValueError(f'unknown nodes {unknown}: expected some of {list(NODES)}')
    node_files = {n: tuple([*default_params_files(n), *files]) for n in names}
    from inflarm_bringup.ros.lockstep import LockstepNodes

    with LockstepNodes({n: NODES[n] for n in names}, node_files) as nodes_under_test:
        chosen = select_nodes([nodes_under_test.io(n) for n in names],
                              {t: i.msgtype for t, i in info.topics.items()},
                              requested=nodes is not None)
        nodes_under_test.keep(io.name for io in chosen)
        produced = {t for io in chosen for t in io.outputs}
        input_topics = sorted({t for io in chosen for t in io.inputs
                               if t in info.topics and t not in produced})
        recorded: dict[str, list[tuple[int, int | None]]] = {}
        for m in read_messages(bag, sorted(produced & set(info.topics))):
            recorded.setdefault(m.topic, []).append((m.timestamp_ns, _stamp_of(m)))
        end_ns = info.start_ns + info.duration_ns
        timers = tuple(s for io in chosen
                       for s in _schedules(io, recorded, info.start_ns, end_ns))
        inputs = list(read_messages(bag, input_topics))
        subscribers = {t: [io.name for io in chosen if t in io.inputs] for t in input_topics}
        firings = {io.name: sorted(t for s in timers if s.node == io.name and s.by == 'time'
                                   and s.aligned_to for t in s.due_ns) for io in chosen}
        deliveries = retime_inputs(inputs, subscribers, _consumed(chosen, inputs, recorded),
                                   firings, order)
        nodes_under_test.run(deliveries, info.start_ns, end_ns,
                             {(s.node, s.index): s.due_ns for s in timers})
        counts = Counter(m.topic for m in inputs)
        outputs = tuple(nodes_under_test.outputs)
        timer_outputs = frozenset(nodes_under_test.timer_topics)
    return Replay(pathlib.Path(bag), chosen, {io.name: node_files[io.name] for io in chosen},
                  {t: counts[t] for t in input_topics}, timers, outputs, info.start_ns, end_ns,
                  timer_outputs)


def regression(bag: str | os.PathLike, result: Replay,
               tolerances: Tolerances = DEFAULT_TOLERANCES,
               skip_start_s: float = SKIP_START_S,
               alternative: Replay | None = None) -> Report:
    """Compare the replay ``result`` with the outputs recorded in ``bag``: every compared
    output topic of the nodes under test that the bag holds, each from ``skip_start_s`` [s]
    after its node's first recorded output (the start-up, `start_times`). A recorded output
    of a timer (``result.timer_outputs``) out of tolerance against ``result`` may match
    ``alternative`` instead: the replay with the other order of its ambiguous inputs
    (``replay(..., order='before')``; module docstring)."""
    info = bag_info(bag)
    topics = [t for t in result.compared_topics if t in info.topics]
    starts = start_times(bag, result.nodes, skip_start_s)
    report = compare(read_messages(bag, topics), result.outputs, tolerances, topics,
                     starts, result.timer_outputs,
                     () if alternative is None else alternative.outputs)
    not_compared = tuple(t for t in result.compared_topics if t not in info.topics)
    return Report(report.topics, not_compared)


def start_times(bag: str | os.PathLike, nodes: Sequence[NodeIo],
                skip_start_s: float = SKIP_START_S) -> dict[str, int]:
    """Output topic -> when its comparison starts [ns]: ``skip_start_s`` after the first
    output of its node recorded in ``bag`` (a node's first callbacks and the recorder's first
    messages of a topic lag behind).

    Raises
    ------
    ValueError
        When ``skip_start_s`` is not a finite number >= 0.
    """
    if not (isinstance(skip_start_s, (int, float)) and np.isfinite(skip_start_s)
            and skip_start_s >= 0):
        raise ValueError(f'skip_start_s: expected a finite number >= 0 [s], got '
                         f'{skip_start_s!r}')
    info = bag_info(bag)
    starts = {}
    for io in nodes:
        topics = [t for t in io.compared_outputs if t in info.topics]
        first = min((m.timestamp_ns for m in read_messages(bag, topics)), default=None) \
            if topics else None
        if first is not None:
            for t in io.compared_outputs:
                starts[t] = first + round(skip_start_s * 1e9)
    return starts


def write_outputs(out: pathlib.Path, bag: str | os.PathLike, result: Replay,
                  report: Report) -> None:
    """``out/replayed`` (a bag of the replayed outputs, with the recorded QoS where the bag
    has the topic), ``out/report.md`` and ``out/report.csv``."""
    info = bag_info(bag)
    out.mkdir(parents=True, exist_ok=True)
    with BagWriter(out / 'replayed') as writer:
        for topic, msgtype in sorted({(m.topic, m.msgtype) for m in result.outputs}):
            recorded = info.topics.get(topic)
            writer.add_topic(topic, msgtype, recorded.offered_qos if recorded else ())
        for m in result.outputs:
            writer.write(m.topic, m.timestamp_ns, m.data)
    (out / 'report.md').write_text(f'# Bag regression of `{bag}`\n\n{describe(result)}\n\n'
                                   f'{report.markdown()}', encoding='utf-8')
    (out / 'report.csv').write_text(report.csv(), encoding='utf-8')


def describe(result: Replay) -> str:
    """What was replayed: the nodes, the inputs from the bag, the timers."""
    inputs = ', '.join(f'{t} ({n})' for t, n in result.inputs.items()) or 'none'
    timers = ', '.join(
        f'{s.node} {s.period_ns * 1e-9:g} s '
        + (f'aligned to {s.aligned_to} {s.by}s ({s.recorded_firings} of {len(s.due_ns)} '
           'firings as recorded)' if s.aligned_to else 'from the start')
        for s in result.timers) or 'none'
    return '\n'.join([
        f'nodes under test: {", ".join(io.name for io in result.nodes)}',
        f'simulated time: {(result.end_ns - result.start_ns) * 1e-9:.3f} s',
        f'inputs from the bag: {inputs}',
        f'timers: {timers}',
        f'outputs replayed: {len(result.outputs)}'])


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-bag-regression``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Replay the inputs recorded in a bag into the estimation and '
        'control nodes, in lock step on the recorded time, and compare their outputs with '
        'the recorded ones.',
        epilog=f'Exit status: 0 within tolerance, 1 not, 2 bad arguments or bag. Tolerance '
        f'quantities: {", ".join(f"{q} [{u}]" if u else q for q, u in UNITS.items())}; '
        f'defaults: {", ".join(f"{k}={v:g}" for k, v in DEFAULT_TOLERANCES.values.items())}.')
    parser.add_argument('bag', help='rosbag2 directory (sqlite3 or MCAP)')
    parser.add_argument('--nodes', default=None,
                        help=f'comma-separated nodes to test, of {",".join(NODES)} '
                             "(default: those the bag's topics apply to)")
    parser.add_argument('--params-file', action='extend', nargs='+', default=[], metavar='F',
                        help='parameter file for the nodes (after their installed configs); '
                             'repeatable')
    parser.add_argument('--out', default=None, metavar='DIR',
                        help='write the replayed outputs (DIR/replayed, a bag) and the report '
                             '(DIR/report.md, DIR/report.csv)')
    parser.add_argument('--skip-start-s', type=float, default=SKIP_START_S, metavar='S',
                        help="the start-up not compared [s] from each node's first recorded "
                             f'output (default {SKIP_START_S:g}; 0 compares everything)')
    parser.add_argument('--tolerance', action='extend', nargs='+', default=[],
                        metavar='[TOPIC:]QUANTITY=VALUE',
                        help="absolute tolerance in SI units, e.g. 'force=0.01' or "
                             "'estimated_wrench:force=0.1'; 'unmatched=0.1' is the share of "
                             'messages allowed unmatched; repeatable')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; returns the exit status (0 within tolerance, 1 not, 2 bad arguments)."""
    return run_command(build_parser(), argv, _compare, errors=(ValueError,), error_status=2)


def _compare(args: argparse.Namespace) -> int:
    tolerances = DEFAULT_TOLERANCES.updated(args.tolerance)
    nodes = None
    if args.nodes is not None:
        nodes = [n.strip() for n in args.nodes.split(',') if n.strip()]
        if not nodes or any(n not in NODES for n in nodes):
            raise ValueError(f'--nodes: expected names of {list(NODES)}, got {args.nodes!r}')
    out = pathlib.Path(args.out) if args.out else None
    if out is not None and (out / 'replayed').exists():
        raise ValueError(f"--out: {str(out / 'replayed')!r} exists: a bag is never "
                         'written over')
    if not (np.isfinite(args.skip_start_s) and args.skip_start_s >= 0):
        raise ValueError(f'--skip-start-s: expected a number >= 0 [s], got '
                         f'{args.skip_start_s!r}')
    result = replay(args.bag, nodes, args.params_file)
    other = replay(args.bag, nodes, args.params_file, order='before')
    report = regression(args.bag, result, tolerances, args.skip_start_s, other)
    print(f'{PROG}: {args.bag}\n{describe(result)}\n')
    print(report.table())
    if out is not None:
        try:
            write_outputs(out, args.bag, result, report)
        except (OSError, ValueError) as err:
            print(f'{PROG}: error: cannot write {out}: {err}', file=sys.stderr)
            return 2
        print(f'wrote {out / "replayed"}, {out / "report.md"}, {out / "report.csv"}')
    return 0 if report.passed else 1


if __name__ == '__main__':
    sys.exit(main())
