"""``inflarm-bag-regression``: replay a recorded run's callbacks into the estimation and control
nodes and compare their outputs with the recorded ones (``--help``).

BAG is a rosbag2 directory (sqlite3 or MCAP) of a run whose nodes under test had the parameter
``callback_log`` true: each published a `inflarm_msgs_json.CallbackRecord` per callback on
``/callback_log`` (which callback, the node's clock, the message it took). Exit status: 0 when
every compared topic is within tolerance, 1 when one is not, 2 on bad arguments, an unreadable
bag, a bag without a node's records, or a node that cannot be built from its parameters.

Nodes under test (`NODES`): the classes as they are, with the parameter files the system gives
them (``inflarm_bringup.systems``), then ``--params-file`` (what the run was started with);
by default every one whose records the bag holds.

Replay (`replay`), deterministic by construction (`inflarm_bringup.ros.lockstep`): the records
of all nodes under test in time order (the nodes ran on one machine, one clock); for each, the
node's clock is set to its time and the callback it names is called, a subscription's with the
message it names: the one with that stamp and digest that a node under test published in the
replay (``estimated_wrench`` into ``elastostatic_ik``), else the bag's. So each node takes the
same messages in the same order and its timers fire when they fired. A record whose message is
in neither is skipped and counted: the recorder had not yet subscribed, or lost it. Not
replayed: service calls, and when a background job finished (in simulated time computing takes
none). The first ``--skip-start-s`` after each node's first recorded output are not compared:
what a node took before the recorder subscribed is not in the bag. Comparison:
`inflarm_bringup.bag_compare`, each recorded output timed at the callback whose record lists it
(`inflarm_bringup.ros.lockstep.published_at`), as its replayed twin is.
"""

import argparse
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import os
import pathlib
import sys

import numpy as np

from inflarm_bringup.bag_compare import DEFAULT_TOLERANCES, UNITS, Report, Tolerances, compare
from inflarm_bringup.node_io import NodeIo
from inflarm_hw.bag import BagMessage, BagWriter, bag_info, deserialize, read_messages
from inflarm_msgs_json import CALLBACK_LOG_TOPIC, CallbackRecord, MessageError, decode
from inflarm_msgs_json.cli import run_command

__all__ = [
    'NODES',
    'SKIP_START_S',
    'Replay',
    'callback_records',
    'main',
    'regression',
    'replay',
]

PROG = 'inflarm-bag-regression'
#: The nodes that can be tested, as the simulated system runs them (``inflarm_bringup.systems``).
NODES = ('load_estimator', 'elastostatic_ik', 'pressure_controller')
#: The start-up not compared by default [s]: from each node's first recorded output.
SKIP_START_S = 1.0


@dataclass(frozen=True)
class Replay:
    """A replay's outcome: the nodes under test and each one's parameter files, in order; input
    topic -> messages taken from the bag; node -> callbacks run; the records skipped, with their
    node (their message is in neither the bag nor the replay); everything the nodes published,
    in order, stamped with the simulated time [ns]; every node's records in the bag
    (`callback_records`), which time the recorded outputs."""

    nodes: tuple[NodeIo, ...]
    params_files: Mapping[str, tuple[str, ...]]
    inputs: Mapping[str, int]
    callbacks: Mapping[str, int]
    skipped: tuple[tuple[str, CallbackRecord], ...]
    outputs: tuple[BagMessage, ...]
    records: Mapping[str, Sequence[CallbackRecord]]

    @property
    def compared_topics(self) -> list[str]:
        """The outputs of the nodes under test that are compared (diagnostics are not)."""
        return sorted({t for io in self.nodes for t in io.compared_outputs})


def callback_records(bag: str | os.PathLike) -> dict[str, list[CallbackRecord]]:
    """Node name (without namespace) -> its `CallbackRecord`s in ``bag``, in record order.

    Raises
    ------
    ValueError
        When a record does not decode.
    """
    records: dict[str, list[CallbackRecord]] = {}
    if CALLBACK_LOG_TOPIC not in bag_info(bag).topics:
        return records
    for m in read_messages(bag, [CALLBACK_LOG_TOPIC]):
        try:
            record = decode(deserialize(m.data, m.msgtype).data, expected=CallbackRecord)
        except (MessageError, ValueError) as err:
            raise ValueError(f'{CALLBACK_LOG_TOPIC} at {m.timestamp_ns} ns: {err}') from err
        records.setdefault(record.node.rsplit('/', 1)[-1], []).append(record)
    return records


def replay(bag: str | os.PathLike, nodes: Sequence[str] | None = None,
           params_files: Sequence[str | os.PathLike] = ()) -> Replay:
    """Replay the callbacks recorded in ``bag`` into the nodes under test (module docstring).

    Parameters
    ----------
    bag : path-like
        A rosbag2 directory.
    nodes : sequence of str, optional
        Names from `NODES`; default: those whose records the bag holds.
    params_files : sequence of path-like
        Parameter files for every node, after the system's files.

    Returns
    -------
    Replay

    Raises
    ------
    ValueError
        On an unreadable bag, an unknown node, a missing parameter file, a bag without the
        records of a node, or a node that cannot be built from its parameters.
    """
    info = bag_info(bag)
    files = [str(f) for f in params_files]
    for f in files:
        if not os.path.isfile(f):
            raise ValueError(f'parameter file {f!r} does not exist')
    records = callback_records(bag)
    names = [n for n in NODES if n in records] if nodes is None else list(dict.fromkeys(nodes))
    unknown = [n for n in names if n not in NODES]
    if unknown or (nodes is not None and not names):
        raise ValueError(f'unknown nodes {unknown}: expected some of {list(NODES)}')
    lacking = [n for n in names if n not in records] if names else list(NODES)
    if lacking:
        raise ValueError(f'the bag holds no {CALLBACK_LOG_TOPIC} records of {lacking}: record '
                         'the run with the parameter callback_log true on them')
    from inflarm_bringup.launcher import node_class
    from inflarm_bringup.ros.lockstep import LockstepNodes
    from inflarm_bringup.systems import sim

    system = {node.executable: node for node in sim()}
    node_files = {n: (*system[n].parameter_files(), *files) for n in names}
    with LockstepNodes({n: node_class(system[n]) for n in names}, node_files) as under_test:
        ios = tuple(under_test.io(n) for n in names)
        for io in ios:
            for topic, msgtype in {**io.inputs, **io.outputs}.items():
                if topic in info.topics and info.topics[topic].msgtype != msgtype:
                    raise ValueError(f'{topic} holds {info.topics[topic].msgtype} in the bag, '
                                     f'but {io.name} takes or publishes it as {msgtype}')
        for name in names:
            unknown = {r.callback for r in records[name]} - set(
                under_test.nodes[name].guarded_callbacks)
            if unknown:
                raise ValueError(f'{name} has no callbacks {sorted(unknown)} that the bag '
                                 'records: was the run started with other parameters?')
        topics = sorted({t for io in ios for t in io.inputs} & set(info.topics))
        recorded: dict[str, list[BagMessage]] = {}
        for m in read_messages(bag, topics):
            recorded.setdefault(m.topic, []).append(m)
        ordered = sorted(((n, r) for n in names for r in records[n]),
                         key=lambda item: item[1].time_ns)  # stable: each node's own order
        callbacks, inputs, skipped = under_test.run(ordered, recorded)
        return Replay(ios, node_files, inputs, callbacks, skipped, tuple(under_test.outputs),
                      records)


def regression(bag: str | os.PathLike, result: Replay,
               tolerances: Tolerances = DEFAULT_TOLERANCES,
               skip_start_s: float = SKIP_START_S) -> Report:
    """Compare the replay ``result`` of ``bag`` with the outputs recorded in it: every compared
    output topic of the nodes under test that the bag holds, each from ``skip_start_s`` [s]
    after its node's first recorded output; each recorded output timed at the callback that
    published it (`published_at`).

    Raises
    ------
    ValueError
        When ``skip_start_s`` is not a finite number >= 0.
    """
    if not (isinstance(skip_start_s, (int, float)) and np.isfinite(skip_start_s)
            and skip_start_s >= 0):
        raise ValueError(f'skip_start_s: expected a finite number >= 0 [s], got '
                         f'{skip_start_s!r}')
    from inflarm_bringup.ros.lockstep import published_at

    in_bag = bag_info(bag).topics
    topics = [t for t in result.compared_topics if t in in_bag]
    records = [r for node in result.records.values() for r in node]
    recorded = published_at(records, read_messages(bag, topics))
    starts = {}
    for io in result.nodes:
        first = min((m.timestamp_ns for m in recorded if m.topic in io.compared_outputs),
                    default=None)
        if first is not None:
            starts.update(dict.fromkeys(io.compared_outputs, first + round(skip_start_s * 1e9)))
    report = compare(recorded, result.outputs, tolerances, topics, starts)
    return Report(report.topics, tuple(t for t in result.compared_topics if t not in in_bag))


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
                                   f'```\n{report.table()}\n```\n', encoding='utf-8')
    (out / 'report.csv').write_text(report.csv(), encoding='utf-8')


def describe(result: Replay) -> str:
    """What was replayed: the nodes, their callbacks, the inputs from the bag."""
    inputs = ', '.join(f'{t} ({n})' for t, n in sorted(result.inputs.items())) or 'none'
    skipped = Counter(n for n, _ in result.skipped)
    callbacks = ', '.join(f'{n} {ran}' + (f' ({skipped[n]} skipped: message not recorded)'
                                          if skipped[n] else '')
                          for n, ran in result.callbacks.items())
    return '\n'.join([
        f'nodes under test: {", ".join(io.name for io in result.nodes)}',
        f'callbacks replayed: {callbacks}',
        f'inputs from the bag: {inputs}',
        f'outputs replayed: {len(result.outputs)}'])


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-bag-regression``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Replay the callbacks recorded in a bag into the estimation '
        'and control nodes, in their recorded order on the recorded time, and compare their '
        'outputs with the recorded ones.',
        epilog=f'Exit status: 0 within tolerance, 1 not, 2 bad arguments or bag. Tolerance '
        f'quantities: {", ".join(f"{q} [{u}]" if u else q for q, u in UNITS.items())}; '
        f'defaults: {", ".join(f"{k}={v:g}" for k, v in DEFAULT_TOLERANCES.values.items())}.')
    parser.add_argument('bag', help='rosbag2 directory (sqlite3 or MCAP)')
    parser.add_argument('--nodes', default=None,
                        help=f'comma-separated nodes to test, of {",".join(NODES)} '
                             '(default: those whose callback records the bag holds)')
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
    result = replay(args.bag, nodes, args.params_file)
    report = regression(args.bag, result, tolerances, args.skip_start_s)
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
