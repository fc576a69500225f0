"""Records topics into a rosbag2 bag (sqlite3 or MCAP): ``ros2 bag record`` for this workspace.

Each topic's type is discovered from the ROS graph (retrying until every topic has a
publisher), and every message is stored as the CDR bytes a raw subscription receives, stamped
with its receive time on the node's clock. The bag is finished (index and metadata.yaml) when
the node is destroyed, which ``main`` does on Ctrl-C and SIGTERM: a recording stopped that way
is a complete bag, while a SIGKILLed one is unreadable.

Subscribes:
    each of ``topics`` (any ROS 2 Jazzy message type, raw CDR), with the QoS its publishers
    offer (`recording_qos`): latched topics such as ``robot_description`` are recorded.
Parameters:
    topics (string[], read-only): topics to record; required. Relative names resolve in the
        node's namespace, and remappings apply.
    output (string, read-only): bag directory to create; it must not exist. Empty: a
        ``rosbag2_YYYY_MM_DD-HH_MM_SS`` directory in the working directory.
    storage (string, read-only): ``sqlite3`` (rosbag2's default) or ``mcap``.
    discovery_timeout_s (double): warn about topics still without a publisher after this long,
        and again every so long; the recorder keeps looking for them.
"""

import functools
import importlib
import os
import time

from rclpy.exceptions import InvalidTopicNameException
import rclpy.logging
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from inflarm_hw.bag import STORAGES, BagWriter, TopicQos
from inflarm_msgs_json import CALLBACK_LOG_TOPIC
from inflarm_msgs_json.ros.node import CALLBACK_LOG_QOS, GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import subscription_events
from inflarm_msgs_json.ros.spin import spin_node

RECORD_DEPTH = 100  # absorbs bursts while the callback writes to disk
DISCOVERY_PERIOD_S = 0.2

PARAMETERS = (
    # A string array without a default: rclpy would type an empty list as a byte array.
    Parameter('topics', RosParameter.Type.STRING_ARRAY, 'topics to record (required)',
              read_only=True),
    Parameter('output', '', 'bag directory to create; empty: rosbag2_<date>-<time>',
              read_only=True),
    Parameter('storage', 'sqlite3', f'storage plugin, one of {list(STORAGES)}', read_only=True),
    Parameter('discovery_timeout_s', 5.0,
              'warn about topics without a publisher after this long [s], and every so long',
              range=(0.1, 3600.0)),
)


def message_class(msgtype: str) -> type:
    """The rclpy message class of ``'pkg/msg/Name'`` (without rosidl_runtime_py).

    Raises
    ------
    ValueError
        When the type name is malformed or its package is not installed.
    """
    parts = msgtype.split('/')
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"expected a type name like 'sensor_msgs/msg/JointState', got "
                         f'{msgtype!r}')
    package, kind, name = parts
    try:
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ImportError, AttributeError) as err:
        raise ValueError(f'message type {msgtype} is not installed: {err}') from err


def offered_qos(profile: QoSProfile) -> TopicQos:
    """A publisher's QoS, as the bag stores it."""
    return TopicQos.parse(profile.reliability.name, profile.durability.name,
                          profile.history.name, profile.depth)


def recording_qos(offered: list[TopicQos], depth: int = RECORD_DEPTH) -> QoSProfile:
    """The subscription QoS that matches every offered profile and loses the least.

    Reliable only where every publisher is reliable (a reliable subscription gets nothing from a
    best-effort publisher); transient-local only where every publisher is (a transient-local one
    gets nothing from a volatile publisher), and then their latched history reaches the recorder.
    """
    reliable = all(q.reliability == 'reliable' for q in offered)
    latched = all(q.durability == 'transient_local' for q in offered)
    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


class BagRecorder(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('bag_recorder', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS)
        self.topics = self.resolve_topics(p['topics'])
        if p['storage'] not in STORAGES:
            raise ValueError(f"storage must be one of {list(STORAGES)}, got {p['storage']!r}")
        output = p['output'] or time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
        self.bag = BagWriter(os.path.abspath(output), storage=p['storage'])  # checks output
        self.pending = list(self.topics)
        #: Topic -> the publishers its subscription is matched with now.
        self.matched_publishers: dict[str, int] = {}
        self.start_time = time.monotonic()
        self.discovery_timer = self.create_guarded_timer(DISCOVERY_PERIOD_S, self.discover)
        self.get_logger().info(
            f'ready: recording {self.topics} to {self.bag.path} ({self.bag.storage})')

    def resolve_topics(self, topics: list[str] | None) -> list[str]:
        if not topics:
            raise ValueError("parameter 'topics' is required: the topics to record, e.g. "
                             "-p topics:='[joint_states]'")
        try:
            resolved = [self.resolve_topic_name(topic) for topic in topics]
        except InvalidTopicNameException as err:
            raise ValueError(f'topics: {err}') from err
        duplicates = sorted({t for t in resolved if resolved.count(t) > 1})
        if duplicates:
            raise ValueError(f'topics lists {duplicates} more than once')
        return resolved

    def discover(self) -> None:
        """Subscribe to every pending topic that now has a publisher; warn about the rest."""
        types = dict(self.get_topic_names_and_types())
        for topic in list(self.pending):
            publishers = self.get_publishers_info_by_topic(topic)
            if topic not in types or not publishers:
                continue
            self.pending.remove(topic)
            msgtype = types[topic][0]
            if len(types[topic]) > 1:
                self.get_logger().warning(
                    f'{topic} is published with several types {types[topic]}: recording '
                    f'{msgtype}')
            offered = [offered_qos(info.qos_profile) for info in publishers]
            try:
                msg_class = message_class(msgtype)
                self.bag.add_topic(topic, msgtype, offered)
            except ValueError as err:
                self.get_logger().error(f'{topic} will not be recorded: {err}')
                continue
            # every callback record: one lost is a callback the bag regression cannot replay
            qos = recording_qos(offered, CALLBACK_LOG_QOS.depth if topic == CALLBACK_LOG_TOPIC
                                else RECORD_DEPTH)
            self.create_guarded_subscription(
                msg_class, topic, functools.partial(self.on_message, topic), qos, raw=True,
                event_callbacks=subscription_events(
                    self, topic, matched=functools.partial(self.on_matched, topic)))
            self.get_logger().info(
                f'recording {topic} ({msgtype}, {qos.reliability.name.lower()}, '
                f'{qos.durability.name.lower()})')
        if not self.pending:
            self.discovery_timer.cancel()
            return
        timeout = self.params['discovery_timeout_s']
        if time.monotonic() - self.start_time >= timeout:
            self.problems.warn('discovery', f'no publisher yet on {self.pending} after '
                                            f'{timeout} s; still looking', kind='no publisher')

    def on_matched(self, topic: str, status) -> None:
        # Found is not matched: each publisher is matched on its own, up to seconds later
        # under load, and what it published before is not recorded.
        self.matched_publishers[topic] = count = status.current_count
        self.get_logger().info(
            f'{topic}: recording from {count} publisher{"" if count == 1 else "s"}')

    def on_message(self, topic: str, data: bytes) -> None:
        # Receive time, as ros2 bag record stores: every type has one (std_msgs/String has no
        # header), it orders the topics as the subscribers saw them, so replays keep that
        # timing, and it is on the node's clock (simulated time under use_sim_time).
        if not self.bag.closed:
            self.bag.write(topic, self.get_clock().now().nanoseconds, data)

    def close_bag(self) -> None:
        """Finish the bag (metadata.yaml) and log what it holds. Idempotent."""
        if self.bag.closed:
            return
        self.bag.close()
        counts = ', '.join(f'{topic} {count}' for topic, count in self.bag.counts.items())
        missing = f'; never published: {self.pending}' if self.pending else ''
        # After Ctrl-C the context, and with it the node logger's rosout publisher, is already
        # shut down: log to the console only (a logger of no node).
        logger = (self.get_logger() if self.context.ok()
                  else rclpy.logging.get_logger(f'{self.get_name()}.bag'))
        logger.info(
            f'bag closed: {self.bag.path}: {sum(self.bag.counts.values())} messages '
            f'({counts or "none"}){missing}')

    def destroy_node(self) -> None:
        try:
            self.close_bag()
        finally:
            super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(BagRecorder, args)


if __name__ == '__main__':
    main()
