"""The nodes under test of the bag regression (``inflarm_bringup.bag_regression``), replayed
callback by callback in this process: its rclpy half.

The nodes are built in a private rclpy context with DDS discovery off (nothing reaches another
process), on simulated time, and never spun. Their publishers are a `Publisher` subclass
(``create_publisher``'s ``publisher_class``) that captures each message as canonical CDR at the
simulated time. A node's background jobs (`LatestJobWorker`) are waited for after each callback.
"""

from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
import contextlib
import importlib
import os

import numpy as np
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message
from rclpy.time import Time

from inflarm_bringup.node_io import INFRASTRUCTURE_TOPICS, NodeIo
from inflarm_hw.bag import BagMessage, typestore
from inflarm_msgs_json import CallbackRecord
from inflarm_msgs_json.ros.node import message_key
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


def _by_key(messages: Iterable[BagMessage], msg_type: type) -> dict[tuple, list[bytes]]:
    """``{(stamp, digest): [CDR, ...]}`` of ``messages`` (`message_key`), in their order."""
    index: dict[tuple, list[bytes]] = defaultdict(list)
    for m in messages:
        index[message_key(deserialize_message(m.data, msg_type))].append(m.data)
    return index


class LockstepNodes:
    """Nodes built for a replay; a context manager that destroys them on exit.

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
        #: What the nodes published, in order, stamped with the simulated time.
        self.outputs: list[BagMessage] = []
        self._published: dict[tuple, list[bytes]] = defaultdict(list)  # by (topic, *key)
        self._now_ns = 0
        try:
            for name, path in classes.items():
                self.nodes[name] = self._build(name, path, params_files.get(name, ()))
        except BaseException:
            self.close()
            raise

    def _build(self, name: str, path: str, files: Sequence[str]) -> Node:
        replay = self

        class Captured(Publisher):
            def publish(self, msg: object) -> None:
                if self.topic_name in INFRASTRUCTURE_TOPICS:
                    super().publish(msg)
                else:
                    replay._capture(self.topic_name, msg)

        class Replayed(node_class(path)):
            def create_publisher(self, *args, **kwargs) -> Publisher:
                return super().create_publisher(*args, **kwargs, publisher_class=Captured)

        args = ['--ros-args']
        for file in files:
            args += ['--params-file', str(file)]
        try:
            return Replayed(context=self.context, cli_args=args, use_global_arguments=False,
                            parameter_overrides=[Parameter('use_sim_time', value=True),
                                                 Parameter('callback_log', value=False)])
        except (ValueError, TypeError, ParameterException, _rclpy.RCLError) as err:
            raise ValueError(f'{name}: cannot be built from its parameters ({", ".join(files)})'
                             f': {err}') from err

    def io(self, name: str) -> NodeIo:
        """What the node ``name`` subscribes to and publishes."""
        node = self.nodes[name]
        return NodeIo(
            name,
            {s.topic_name: msgtype_of(s.msg_type) for s in node.subscriptions
             if s.topic_name not in INFRASTRUCTURE_TOPICS},
            {p.topic_name: msgtype_of(p.msg_type) for p in node.publishers
             if p.topic_name not in INFRASTRUCTURE_TOPICS})

    def _capture(self, topic: str, msg: object) -> None:
        message = BagMessage(topic, msgtype_of(type(msg)), self._now_ns, to_cdr(msg))
        self.outputs.append(message)
        self._published[(topic, *message_key(msg))].append(message.data)

    def run(self, records: Iterable[tuple[str, CallbackRecord]],
            recorded: Mapping[str, Sequence[BagMessage]]
            ) -> tuple[dict[str, int], list[tuple[str, CallbackRecord]]]:
        """Run the callbacks ``records`` name, in their order.

        Parameters
        ----------
        records : iterable of (str, CallbackRecord)
            Node name and record, in time order.
        recorded : mapping of str to sequence of BagMessage
            Input topic -> the bag's messages, in record order. A subscription callback takes
            the first message of its topic with the record's stamp and digest that a node
            under test published, else that the bag holds; each node takes each once.

        Returns
        -------
        dict of str to int, list of (str, CallbackRecord)
            Node name -> callbacks run; the records skipped (their message in neither).
        """
        workers = {name: [w for w in vars(node).values() if isinstance(w, LatestJobWorker)]
                   for name, node in self.nodes.items()}
        # (topic, msg type) -> {(stamp, digest): CDR in record order}, built on first use
        inputs: dict[tuple[str, type], dict[tuple, list[bytes]]] = {}
        taken: Counter[tuple] = Counter()  # (node, (topic, stamp, digest)) -> messages taken
        ran = Counter({name: 0 for name in self.nodes})
        skipped = []
        for name, record in records:
            node = self.nodes[name]
            msg_type, callback = node.guarded_callbacks[record.callback]
            self._now_ns = record.time_ns
            node.get_clock().set_ros_time_override(Time(nanoseconds=record.time_ns))
            if msg_type is None:
                callback()
            else:
                key = (record.callback, record.stamp_ns, record.digest)
                if (record.callback, msg_type) not in inputs:
                    inputs[(record.callback, msg_type)] = _by_key(
                        recorded.get(record.callback, ()), msg_type)
                # the node's n-th message of this key: replayed if a node published it
                n = taken[(name, key)]
                source = self._published.get(key, [])
                if n >= len(source):
                    source = inputs[(record.callback, msg_type)].get(key[1:], [])
                if n >= len(source):
                    skipped.append((name, record))
                    continue
                taken[(name, key)] += 1
                callback(deserialize_message(source[n], msg_type))
            for worker in workers[name]:
                worker.wait()
            ran[name] += 1
        return dict(ran), skipped

    def close(self) -> None:
        for node in self.nodes.values():
            node.destroy_node()
        self.nodes.clear()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'LockstepNodes':
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
