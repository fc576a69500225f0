"""rosbag2 bags (sqlite3 and MCAP) without the ros2 CLI: read, write and decode, via ``rosbags``.

Messages are kept as the CDR bytes that went over the wire: the recorder stores what a raw
subscription (``create_subscription(..., raw=True)``) delivers and the player publishes those
bytes unchanged, so nothing is re-serialized on the way. ``deserialize`` decodes them with the
``rosbags`` Jazzy typestore for offline analysis. Bags are written in the Jazzy metadata format
(version 8) that ``ros2 bag`` uses.

Topic names in a bag are fully qualified (``/joint_states``); where a name is asked for, a
relative one (``joint_states``) means the same topic in the root namespace.
"""

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
import functools
import pathlib
from types import TracebackType
from typing import Any, NamedTuple, Self

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore

__all__ = [
    'STORAGES',
    'BagInfo',
    'BagMessage',
    'BagWriter',
    'TopicInfo',
    'TopicQos',
    'bag_info',
    'deserialize',
    'normalize_topic',
    'read_messages',
    'select_topics',
    'serialize',
    'typestore',
]

STORAGES = ('sqlite3', 'mcap')
_PLUGINS = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
_METADATA_VERSION = 9  # what Jazzy's rosbag2 writes (type_description_hash per topic)
_ZERO = QosTime(0, 0)  # rosbag2: the policy's default (infinite deadline, lifespan, lease)


class BagMessage(NamedTuple):
    """One recorded message: its topic, type, record time [ns] and CDR bytes."""

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicQos:
    """The QoS a recorded publisher offered: the policies a player needs to stand in for it.

    reliability : 'reliable' or 'best_effort'.
    durability : 'volatile' or 'transient_local'.
    history : 'keep_last' or 'keep_all'; depth : history depth (0 when unknown).
    """

    reliability: str = 'reliable'
    durability: str = 'volatile'
    history: str = 'keep_last'
    depth: int = 0

    def __post_init__(self) -> None:
        for name, allowed in (('reliability', ('reliable', 'best_effort')),
                              ('durability', ('volatile', 'transient_local')),
                              ('history', ('keep_last', 'keep_all'))):
            if getattr(self, name) not in allowed:
                raise ValueError(f'expected {name} one of {allowed}, got {getattr(self, name)!r}')
        if not (isinstance(self.depth, int) and self.depth >= 0):
            raise ValueError(f'expected depth a non-negative int, got {self.depth!r}')

    def to_rosbags(self) -> Qos:
        return Qos(QosHistory[self.history.upper()], self.depth,
                   QosReliability[self.reliability.upper()],
                   QosDurability[self.durability.upper()], _ZERO, _ZERO,
                   QosLiveliness.AUTOMATIC, _ZERO, False)

    @classmethod
    def parse(cls, reliability: str, durability: str, history: str = 'keep_last',
              depth: int = 0) -> 'TopicQos':
        """From policy names in any case; names that are no choice (``'unknown'``,
        ``'system_default'``, ``'best_available'``) read as the defaults."""
        def pick(value: str, allowed: tuple[str, ...]) -> str:
            value = str(value).lower()
            return value if value in allowed else allowed[0]
        return cls(pick(reliability, ('reliable', 'best_effort')),
                   pick(durability, ('volatile', 'transient_local')),
                   pick(history, ('keep_last', 'keep_all')), max(int(depth), 0))

    @classmethod
    def from_rosbags(cls, qos: Qos) -> 'TopicQos':
        return cls.parse(qos.reliability.name, qos.durability.name, qos.history.name, qos.depth)


@dataclass(frozen=True)
class TopicInfo:
    """A recorded topic: its type, message count and the QoS its publishers offered."""

    msgtype: str
    message_count: int
    offered_qos: tuple[TopicQos, ...] = ()


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds (from its metadata).

    Attributes
    ----------
    path : pathlib.Path
        The bag directory.
    storage : str
        ``'sqlite3'`` or ``'mcap'``.
    topics : dict[str, TopicInfo]
        Recorded topics by fully qualified name.
    message_count : int
    start_ns, duration_ns : int
        Time of the first message and span to the last [ns] (0 for an empty bag).
    """

    path: pathlib.Path
    storage: str
    topics: dict[str, TopicInfo]
    message_count: int
    start_ns: int
    duration_ns: int


@functools.cache
def typestore() -> Any:
    """The ``rosbags`` typestore of ROS 2 Jazzy's message types (built once, ~0.15 s)."""
    return get_typestore(Stores.ROS2_JAZZY)


def normalize_topic(topic: str) -> str:
    """``topic`` fully qualified: ``'joint_states'`` -> ``'/joint_states'``.

    Raises
    ------
    ValueError
        On an empty or non-string name, or a private (``~``) or substituted (``{}``) one.
    """
    if not isinstance(topic, str) or not topic.strip('/'):
        raise ValueError(f'expected a topic name, got {topic!r}')
    if topic.startswith('~') or '{' in topic:
        raise ValueError(f'expected a plain topic name (no ~ or substitutions), got {topic!r}')
    return topic if topic.startswith('/') else '/' + topic


def _check_storage(storage: str) -> StoragePlugin:
    if storage not in _PLUGINS:
        raise ValueError(f'expected storage one of {STORAGES}, got {storage!r}')
    return _PLUGINS[storage]


def _check_msgtype(msgtype: str) -> str:
    if msgtype not in typestore().types:
        raise ValueError(
            f'unknown message type {msgtype!r}: expected a ROS 2 Jazzy type such as '
            "'sensor_msgs/msg/JointState' (the rosbags Jazzy typestore holds no other types)")
    return msgtype


def _open_reader(path: str | pathlib.Path) -> Reader:
    bag = pathlib.Path(path)
    if not bag.is_dir():
        raise ValueError(f'no bag at {str(bag)!r}: expected a rosbag2 directory')
    if not (bag / 'metadata.yaml').is_file():
        raise ValueError(
            f'{str(bag)!r} has no metadata.yaml: not a rosbag2 bag, or a recording that was '
            'not closed cleanly')
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, OSError) as err:
        raise ValueError(f'cannot read the bag {str(bag)!r}: {err}') from err
    return reader


def bag_info(path: str | pathlib.Path) -> BagInfo:
    """What the bag at ``path`` holds.

    Raises
    ------
    ValueError
        When ``path`` is not a readable rosbag2 directory.
    """
    reader = _open_reader(path)
    try:
        topics = {}
        for name, topic in reader.topics.items():
            qos = tuple(TopicQos.from_rosbags(q) for c in topic.connections
                        for q in getattr(c.ext, 'offered_qos_profiles', ()))
            topics[name] = TopicInfo(topic.msgtype or '', topic.msgcount, qos)
        count = reader.message_count
        start = reader.start_time if count else 0
        # rosbags counts the duration up to just after the last message (+1 ns).
        duration = reader.end_time - 1 - start if count else 0
        files = {f.suffix for f in pathlib.Path(path).iterdir()}
        storage = 'mcap' if '.mcap' in files else 'sqlite3'
        return BagInfo(pathlib.Path(path), storage, topics, count, start, duration)
    finally:
        reader.close()


def select_topics(info: BagInfo, topics: Iterable[str] | None) -> list[str]:
    """The fully qualified names of ``topics`` (all when None), checked against the bag.

    Raises
    ------
    ValueError
        When a topic is not in the bag, or ``topics`` is a single string.
    """
    if topics is None:
        return sorted(info.topics)
    if isinstance(topics, str):
        raise ValueError(f'expected a list of topic names, got the string {topics!r}')
    wanted = [normalize_topic(t) for t in topics]
    unknown = sorted(set(wanted) - set(info.topics))
    if unknown:
        raise ValueError(f'topics {unknown} are not in the bag {str(info.path)!r}; it holds '
                         f'{sorted(info.topics)}')
    return sorted(set(wanted))


def read_messages(path: str | pathlib.Path,
                  topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """The messages of the bag at ``path`` in time order, as raw CDR bytes.

    Parameters
    ----------
    path : str or path-like
        A rosbag2 directory (sqlite3 or MCAP storage).
    topics : iterable of str, optional
        Only these topics (relative names mean the root namespace); all when None.

    Returns
    -------
    iterator of BagMessage
        ``(topic, msgtype, timestamp_ns, data)`` tuples. The bag is checked when this is
        called; it is opened for reading when iteration starts and closed when it ends (or
        when the iterator is closed).

    Raises
    ------
    ValueError
        When ``path`` is not a readable bag, or a requested topic is not in it.
    """
    info = bag_info(path)
    selected = select_topics(info, topics)
    return _iterate(info.path, selected)


def _iterate(path: pathlib.Path, topics: Sequence[str]) -> Iterator[BagMessage]:
    if not topics:
        return
    reader = _open_reader(path)
    try:
        connections = [c for c in reader.connections if c.topic in topics]
        for connection, timestamp, data in reader.messages(connections=connections):
            yield BagMessage(connection.topic, connection.msgtype, timestamp, bytes(data))
    finally:
        reader.close()


def deserialize(raw: bytes | memoryview, msgtype: str) -> Any:
    """Decode CDR bytes of ``msgtype`` (e.g. ``'sensor_msgs/msg/JointState'``).

    Returns
    -------
    A ``rosbags`` message object: fields as in the ``.msg`` definition, numeric arrays as
    numpy arrays.

    Raises
    ------
    ValueError
        On an unknown type or bytes that are not a valid message of that type.
    """
    _check_msgtype(msgtype)
    try:
        return typestore().deserialize_cdr(raw, msgtype)
    except (SerdeError, ValueError, IndexError, TypeError, UnicodeDecodeError) as err:
        raise ValueError(f'cannot decode {len(raw)} bytes as {msgtype}: {err}') from err


def serialize(message: Any, msgtype: str) -> bytes:
    """Encode a ``rosbags`` message object (``typestore().types[msgtype](...)``) as CDR.

    Raises
    ------
    ValueError
        On an unknown type or a message that does not fit it.
    """
    _check_msgtype(msgtype)
    try:
        return bytes(typestore().serialize_cdr(message, msgtype))
    except (SerdeError, ValueError, TypeError, AttributeError, KeyError) as err:
        raise ValueError(f'cannot encode {message!r} as {msgtype}: {err}') from err


class BagWriter:
    """A new rosbag2 bag, written topic by topic (a thin context manager around ``rosbags``).

    Usage::

        with BagWriter('run1', storage='mcap') as bag:
            bag.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
            bag.write('/joint_states', stamp_ns, cdr_bytes)

    The bag is complete (index and ``metadata.yaml`` written) only after ``close()``; a
    process killed before that leaves an unreadable bag.

    Parameters
    ----------
    path : str or path-like
        Bag directory to create (with missing parents); it must not exist.
    storage : str
        ``'sqlite3'`` (rosbag2's default) or ``'mcap'``.

    Raises
    ------
    ValueError
        On an existing path or an unknown storage.
    """

    def __init__(self, path: str | pathlib.Path, storage: str = 'sqlite3') -> None:
        plugin = _check_storage(storage)
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise ValueError(f'{str(self.path)!r} exists: a bag is never written over')
        self.storage = storage
        self._writer = Writer(self.path, version=_METADATA_VERSION, storage_plugin=plugin)
        try:
            self._writer.open()
        except (WriterError, OSError) as err:
            raise ValueError(f'cannot create the bag {str(self.path)!r}: {err}') from err
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self.closed = False

    def add_topic(self, topic: str, msgtype: str,
                  offered_qos: Sequence[TopicQos] = ()) -> str:
        """Declare a topic before writing to it; returns its fully qualified name.

        Raises
        ------
        ValueError
            On a bad topic name, a topic already added, or a type not in the Jazzy typestore.
        """
        self._check_open()
        name = normalize_topic(topic)
        if name in self._connections:
            raise ValueError(f'topic {name} was already added')
        _check_msgtype(msgtype)
        self._connections[name] = self._writer.add_connection(
            name, msgtype, typestore=typestore(),
            offered_qos_profiles=[q.to_rosbags() for q in offered_qos])
        self.counts[name] = 0
        return name

    def write(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Append one message's CDR bytes to ``topic``, stamped ``timestamp_ns`` [ns]."""
        self._check_open()
        name = normalize_topic(topic)
        if name not in self._connections:
            raise ValueError(f'topic {name} was not added; add_topic() it first')
        if not (isinstance(timestamp_ns, int) and timestamp_ns >= 0):
            raise ValueError(f'expected timestamp_ns a non-negative int, got {timestamp_ns!r}')
        self._writer.write(self._connections[name], timestamp_ns, data)
        self.counts[name] += 1

    def close(self) -> None:
        """Finish the bag: storage index and ``metadata.yaml``. Idempotent."""
        if self.closed:
            return
        self.closed = True
        self._writer.close()

    def _check_open(self) -> None:
        if self.closed:
            raise ValueError(f'the bag {str(self.path)!r} is closed')

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()
