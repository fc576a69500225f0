"""Nodes under test driven in lock step, in this process: the rclpy half of the bag regression.

`LockstepNodes` builds nodes in a private rclpy context whose DDS discovery is off (nothing they
do reaches another process, and nothing from one reaches them), with ``use_sim_time``. It never
spins them: `LockstepNodes.run` sets their clocks (a ``rosgraph_msgs/Clock`` handed to each
node's own ``/clock`` subscription), hands each input to the callbacks of the subscriptions on
its topic (a message deserialized by rclpy from the CDR bytes), and calls each timer's callback
when it is due. Publishers are replaced by a capture: a published message becomes canonical CDR
(`to_cdr`) with its publish time, and is handed on to the nodes under test that subscribe to
its topic before time moves on. A node's background jobs (`LatestJobWorker`) are waited for
after each callback: in simulated time computing takes none. See
``inflarm_bringup.bag_regression`` for why.
"""

from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
import contextlib
import functools
import heapq
import importlib
import itertools
import os

import numpy as np
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from rclpy.time import Time
from rosgraph_msgs.msg import Clock

from inflarm_bringup.node_io import INFRASTRUCTURE_TOPICS, NodeIo
from inflarm_hw.bag import BagMessage, typestore
from inflarm_msgs_json.ros.worker import LatestJobWorker

__all__ = ['LockstepNodes', 'msgtype_of', 'to_cdr']

_DTYPES = {
    'float': np.float32, 'double': np.float64, 'long double': np.float64, 'char': np.uint8,
    'wchar': np.uint16, 'boolean': np.bool_, 'octet': np.uint8, 'uint8': np.uint8,
    'int8': np.int8, 'uint16': np.uint16, 'int16': np.int16, 'uint32': np.uint32,
    'int32': np.int32, 'uint64': np.uint64, 'int64': np.int64,
}


def msgtype_of(cls: type) -> str:
    """``'sensor_msgs/msg/JointState'`` for the rclpy class ``sensor_msgs.msg.JointState``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def _scalar(value: object, typename: str) -> object:
    if isinstance(value, bytes):  # octet/byte fields hold 1-byte bytes in rclpy
        return value[0]
    if typename == 'char' and isinstance(value, str):
        return ord(value)
    return value


def _to_rosbags(msg: object, msgtype: str) -> object:
    values = {}
    for (name, _), slot in zip(type(msg).get_fields_and_field_types().items(),
                               type(msg).SLOT_TYPES, strict=True):
        values[name] = _convert(getattr(msg, name), slot)
    return typestore().types[msgtype](**values)


def _convert(value: object, slot: object) -> object:
    # slot: the field's rosidl_parser.definition type (SLOT_TYPES), told apart by attributes.
    if hasattr(slot, 'namespaces'):  # NamespacedType: a nested message
        return _to_rosbags(value, '/'.join([*slot.namespaces, slot.name]))
    if hasattr(slot, 'value_type'):  # Array, BoundedSequence, UnboundedSequence
        inner = slot.value_type
        if hasattr(inner, 'typename'):  # of a BasicType
            if isinstance(value, (bytes, bytearray)):
                return np.frombuffer(bytes(value), dtype=np.uint8).copy()
            items = [_scalar(v, inner.typename) for v in value]
            return np.asarray(items, dtype=_DTYPES[inner.typename])
        return [_convert(v, inner) for v in value]
    if hasattr(slot, 'typename'):  # BasicType
        return _scalar(value, slot.typename)
    return value  # strings


def to_cdr(msg: object) -> bytes:
    """Canonical CDR of an rclpy message, as a raw subscription would receive it.

    ``rclpy.serialization.serialize_message`` leaves uninitialized padding and an over-estimated
    length (``ROS_NOTES.md``): its bytes differ from run to run. This converts the message
    field by field to a ``rosbags`` message and serializes that.
    """
    msgtype = msgtype_of(type(msg))
    return bytes(typestore().serialize_cdr(_to_rosbags(msg, msgtype), msgtype))


@contextlib.contextmanager
def _discovery_off():
    """rcl reads ROS_AUTOMATIC_DISCOVERY_RANGE when a context is initialized."""
    old = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'OFF'
    try:
        yield
    finally:
        if old is None:
            del os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']
        else:
            os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = old


def node_class(path: str) -> type[Node]:
    """The class at ``'package.module:Class'``."""
    module, _, name = path.partition(':')
    return getattr(importlib.import_module(module), name)


class LockstepNodes:
    """Nodes built for a lock-step replay; a context manager that destroys them on exit.

    Parameters
    ----------
    classes : mapping of str to str
        Node name -> ``'package.module:Class'`` (a node class taking ``**kwargs``).
    params_files : mapping of str to sequence of str
        Node name -> its parameter files, in the order they apply.

    Raises
    ------
    ValueError
        When a node cannot be built from its parameters (the node and the reason named).
    """

    def __init__(self, classes: Mapping[str, str],
                 params_files: Mapping[str, Sequence[str]]) -> None:
        self.context = rclpy.Context()
        with _discovery_off():
            rclpy.init(context=self.context, args=[])
        self.nodes: dict[str, Node] = {}
        self.outputs: list[BagMessage] = []
        self._pending: deque[BagMessage] = deque()
        self._now_ns = 0
        #: Topics published from a timer callback (the outputs whose timing is the timer's).
        self.timer_topics: set[str] = set()
        self._in_timer = False
        try:
            for name, path in classes.items():
                self.nodes[name] = self._build(name, path, params_files.get(name, ()))
        except BaseException:
            self.close()
            raise

    def _build(self, name: str, path: str, files: Sequence[str]) -> Node:
        args = ['--ros-args']
        for file in files:
            args += ['--params-file', str(file)]
        try:
            node = node_class(path)(
                context=self.context, cli_args=args, use_global_arguments=False,
                parameter_overrides=[Parameter('use_sim_time', value=True)])
        except (ValueError, TypeError, ParameterException, _rclpy.RCLError) as err:
            raise ValueError(f'{name}: cannot be built from its parameters ({", ".join(files)})'
                             f': {err}') from err
        for publisher in node.publishers:
            if publisher.topic_name not in INFRASTRUCTURE_TOPICS:
                msgtype = msgtype_of(publisher.msg_type)
                publisher.publish = functools.partial(self._capture, publisher.topic_name,
                                                      msgtype)
        return node

    def io(self, name: str) -> NodeIo:
        """What the node ``name`` subscribes to and publishes, and its timers' periods."""
        node = self.nodes[name]
        return NodeIo(
            name,
            {s.topic_name: msgtype_of(s.msg_type) for s in node.subscriptions
             if s.topic_name not in INFRASTRUCTURE_TOPICS},
            {p.topic_name: msgtype_of(p.msg_type) for p in node.publishers
             if p.topic_name not in INFRASTRUCTURE_TOPICS},
            tuple(t.timer_period_ns for t in node.timers))

    def keep(self, names: Iterable[str]) -> None:
        """Destroy every node but ``names``."""
        keep = set(names)
        for name in [n for n in self.nodes if n not in keep]:
            self.nodes.pop(name).destroy_node()

    # -- the lock-step loop ----------------------------------------------------------------------

    def _capture(self, topic: str, msgtype: str, msg: object) -> None:
        data = msg if isinstance(msg, bytes) else to_cdr(msg)
        message = BagMessage(topic, msgtype, self._now_ns, data)
        self.outputs.append(message)
        self._pending.append(message)
        if self._in_timer:
            self.timer_topics.add(topic)

    def _set_time(self, now_ns: int, clocks: Sequence[Callable]) -> None:
        if now_ns == self._now_ns:
            return
        self._now_ns = now_ns
        msg = Clock(clock=Time(nanoseconds=now_ns).to_msg())
        for callback in clocks:
            callback(msg)

    def run(self, inputs: Iterable[tuple[BagMessage, Sequence[str]]], start_ns: int,
            end_ns: int, due: Mapping[tuple[str, int], Sequence[int]]) -> int:
        """Deliver ``inputs`` and fire the timers from ``start_ns`` to ``end_ns``.

        Parameters
        ----------
        inputs : iterable of (BagMessage, sequence of str)
            In time order, each with the nodes it goes to (to each of their subscriptions on
            its topic).
        start_ns, end_ns : int
            The simulated time span [ns]: the clocks start at ``start_ns``; timers due up to
            ``end_ns`` fire after the last input.
        due : mapping
            ``(node name, timer index)`` -> the increasing times [ns] the timer fires at; a
            timer not in it fires every period from ``start_ns``. A timer fires before an
            input of the same time only if it is due earlier.

        Returns
        -------
        int
            The number of inputs delivered. The outputs are in ``self.outputs``.
        """
        subscribers: dict[str, list] = {}  # topic -> [(node name, subscription)]
        clocks = []
        for name, node in self.nodes.items():
            for sub in node.subscriptions:
                if sub.topic_name == '/clock':
                    clocks.append(sub.callback)
                elif sub.topic_name not in INFRASTRUCTURE_TOPICS:
                    subscribers.setdefault(sub.topic_name, []).append((name, sub))
        self._now_ns = -1
        self._set_time(start_ns, clocks)
        timers: list[tuple[Node, object, Iterator[int]]] = []
        heap: list[tuple[int, int]] = []  # (due time, index into timers)
        for name, node in self.nodes.items():
            for index, timer in enumerate(node.timers):
                period = timer.timer_period_ns
                times = iter(due.get((name, index), itertools.count(start_ns + period, period)))
                timers.append((node, timer, times))
                first = next(times, None)
                if first is not None:
                    heapq.heappush(heap, (first, len(timers) - 1))

        workers = [w for node in self.nodes.values() for w in vars(node).values()
                   if isinstance(w, LatestJobWorker)]

        def deliver(message: BagMessage, to: Sequence[str] | None = None) -> None:
            for name, sub in subscribers.get(message.topic, ()):
                if to is None or name in to:
                    sub.callback(deserialize_message(message.data, sub.msg_type))

        def drain() -> None:
            for worker in workers:
                worker.wait()
            while self._pending:
                deliver(self._pending.popleft())
                for worker in workers:
                    worker.wait()

        def fire_until(limit_ns: int, inclusive: bool) -> None:
            while heap and (heap[0][0] < limit_ns or (inclusive and heap[0][0] == limit_ns)):
                when, order = heapq.heappop(heap)
                node, timer, times = timers[order]
                later = next(times, None)
                if later is not None:
                    heapq.heappush(heap, (later, order))
                if timer not in node.timers or timer.is_canceled():
                    continue
                self._set_time(when, clocks)
                self._in_timer = True
                try:
                    timer.callback()
                finally:
                    self._in_timer = False
                drain()

        count = 0
        for message, to in inputs:
            fire_until(message.timestamp_ns, inclusive=False)
            self._set_time(message.timestamp_ns, clocks)
            deliver(message, to)
            drain()
            count += 1
        fire_until(end_ns, inclusive=True)
        return count

    def close(self) -> None:
        for node in self.nodes.values():
            node.destroy_node()
        self.nodes.clear()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'LockstepNodes':
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
