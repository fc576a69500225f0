"""The nodes under test of the bag regression (``inflarm_bringup.bag_regression``), replayed
callback by callback in this process: its rclpy half.

The nodes are built in a private rclpy context with DDS discovery off (nothing reaches another
process), on simulated time, and never spun. Their publishers are a `Publisher` subclass
(``create_publisher``'s ``publisher_class``) that captures each message as canonical CDR at the
simulated time. A node's background jobs (`LatestJobWorker`) are waited for after each callback.
"""

from collections import Counter, defaultdict, deque
from collections.abc import Iterable, Mapping, Sequence
import contextlib
import os

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.time import Time

from inflarm_bringup.node_io import INFRASTRUCTURE_TOPICS, NodeIo
from inflarm_hw.bag import BagMessage, typestore
from inflarm_hw.nodes.bag_recorder import message_class
from inflarm_msgs_json import CallbackRecord
from inflarm_msgs_json.ros.node import message_key
from inflarm_msgs_json.ros.worker import LatestJobWorker

__all__ = ['LockstepNodes', 'msgtype_of', 'published_at', 'to_cdr']


def msgtype_of(cls: type) -> str:
    """``'sensor_msgs/msg/JointState'`` for the rclpy class ``sensor_msgs.msg.JointState``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def to_cdr(msg: object) -> bytes:
    """Canonical CDR of an rclpy message, as a raw subscription would receive it.

    ``rclpy.serialization.serialize_message`` leaves uninitialized padding and may over-estimate
    the length (``ROS_NOTES.md``): its bytes differ from run to run, and rosbags' decoder
    refuses the longer ones. They are decoded here without that length check, then encoded.
    """
    msgtype, store = msgtype_of(type(msg)), typestore()
    raw = serialize_message(msg)
    msgdef = store.get_msgdef(msgtype)
    decode = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    return bytes(store.serialize_cdr(decode(raw[4:], 0, msgdef.cls, store)[0], msgtype))


def published_at(records: Iterable[CallbackRecord], messages: Iterable[BagMessage]
                 ) -> list[BagMessage]:
    """``messages`` (recorded, in record order) each timed at the callback that published it,
    as the replay times its outputs, instead of when the recorder received it.

    Each takes the time of the first record not yet taken (``records``: each node's in its
    order) that lists a message of its topic, stamp and digest and began before it was
    received: a topic reaches the recorder in the order it was published. One that no record
    lists keeps its receive time.
    """
    times: dict[tuple, deque[int]] = defaultdict(deque)
    for record in records:
        for m in record.published:
            times[(m.topic, m.stamp_ns, m.digest)].append(record.time_ns)
    classes: dict[str, type] = {}
    timed = []
    for m in messages:
        if m.msgtype not in classes:
            classes[m.msgtype] = message_class(m.msgtype)
        queue = times.get((m.topic, *message_key(deserialize_message(m.data,
                                                                     classes[m.msgtype]))))
        if queue and queue[0] <= m.timestamp_ns:
            m = m._replace(timestamp_ns=queue.popleft())
        timed.append(m)
    return timed


class LockstepNodes(contextlib.AbstractContextManager):
    """Nodes built for a replay from ``classes`` (node name -> node class) and ``params_files``
    (node name -> its parameter files, in the order they apply); a context manager that destroys
    them on exit. Raises ValueError naming the node and the reason when one cannot be built."""

    def __init__(self, classes: Mapping[str, type[Node]],
                 params_files: Mapping[str, Sequence[str]]) -> None:
        self.context = rclpy.Context()
        # rcl reads the discovery range when a context is initialized.
        discovery = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'OFF'
        try:
            rclpy.init(context=self.context, args=[])
        finally:
            os.environ.pop('ROS_AUTOMATIC_DISCOVERY_RANGE')
            if discovery is not None:
                os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = discovery
        self.nodes: dict[str, Node] = {}
        #: What the nodes published, in order, stamped with the simulated time.
        self.outputs: list[BagMessage] = []
        self._published: dict[tuple, list[bytes]] = defaultdict(list)  # by (topic, *key)
        self._now_ns = 0
        try:
            for name, cls in classes.items():
                self.nodes[name] = self._build(name, cls, params_files.get(name, ()))
        except BaseException:
            self.close()
            raise

    def _build(self, name: str, cls: type[Node], files: Sequence[str]) -> Node:
        replay = self

        class Captured(Publisher):
            def publish(self, msg: object) -> None:
                if self.topic_name in INFRASTRUCTURE_TOPICS:
                    super().publish(msg)
                else:
                    replay._capture(self.topic_name, msg)

        class Replayed(cls):
            def create_publisher(self, *args, **kwargs) -> Publisher:
                return super().create_publisher(*args, **kwargs, publisher_class=Captured)

        args = ['--ros-args', *(a for file in files for a in ('--params-file', str(file)))]
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
            ) -> tuple[dict[str, int], dict[str, int], tuple[tuple[str, CallbackRecord], ...]]:
        """Run the callbacks that ``records`` (node name and record, in time order) name.

        A subscription callback takes the node's next message of its topic with the record's
        stamp and digest that a node under test published, else that the bag holds (``recorded``:
        input topic -> messages in record order). Returns node name -> callbacks run, input topic
        -> messages taken from the bag, and the records skipped (their message in neither).
        """
        workers = {name: [w for w in vars(node).values() if isinstance(w, LatestJobWorker)]
                   for name, node in self.nodes.items()}
        # (topic, msg type) -> {(stamp, digest): CDR in record order}, built on first use
        inputs: dict[tuple[str, type], dict[tuple, list[bytes]]] = {}
        taken: Counter[tuple] = Counter()  # (node, (topic, stamp, digest)) -> messages taken
        ran = Counter({name: 0 for name in self.nodes})
        from_bag: Counter[str] = Counter()
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
                    index = inputs[(record.callback, msg_type)] = defaultdict(list)
                    for m in recorded.get(record.callback, ()):
                        index[message_key(deserialize_message(m.data, msg_type))].append(m.data)
                # the node's n-th message of this key: replayed if a node published it
                n = taken[(name, key)]
                source = self._published.get(key, [])
                if n >= len(source):
                    source = inputs[(record.callback, msg_type)].get(key[1:], [])
                    if n >= len(source):
                        skipped.append((name, record))
                        continue
                    from_bag[record.callback] += 1
                taken[(name, key)] += 1
                callback(deserialize_message(source[n], msg_type))
            for worker in workers[name]:
                worker.wait()
            ran[name] += 1
        return dict(ran), dict(from_bag), tuple(skipped)

    def close(self) -> None:
        for node in self.nodes.values():
            node.destroy_node()
        self.nodes.clear()
        rclpy.try_shutdown(context=self.context)

    def __exit__(self, *exc_info) -> None:
        self.close()
