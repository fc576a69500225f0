"""Callbacks that never kill a node: the mixin every inflarm node (plain or lifecycle) uses.

    class SraSim(GuardedCallbacks, Node):
        def __init__(self, **kwargs):
            super().__init__('sra_sim', **kwargs)
            self.create_guarded_subscription(String, 'chamber_pressure_command',
                                             self.on_command, COMMAND_QOS)
            self.create_guarded_timer(0.02, self.step)

A guarded callback reports a rejected input (any ``ValueError``, e.g. `InputError`) as a warning
throttled per kind of problem, and a bug (any other exception) as an error with its traceback;
the node keeps running either way (`inflarm_msgs_json.ros.problems`). Subscriptions also log
incompatible QoS offers, which otherwise drop every message silently.

With the parameter ``callback_log`` true, each guarded subscription and timer callback, once
it ran, publishes a `CallbackRecord` on ``/callback_log``: which callback, the node's clock
when it began (``callback_time``, which a callback reads instead of the clock where the
reading shapes an output) and which message it took, and which it published (the node's
publishers note them), so that each recorded output is compared with the replayed output of its
own callback, however late the recorder received it. ``inflarm-bag-regression`` replays a bag
of them callback by callback, in the recorded order, calling ``guarded_callbacks``.
"""

from collections.abc import Callable
import functools
import threading
import zlib

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.publisher import Publisher
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from std_msgs.msg import String

from inflarm_msgs_json.messages import CALLBACK_LOG_TOPIC, CallbackRecord, PublishedMessage
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.problems import ProblemReporter
from inflarm_msgs_json.ros.qos import subscription_events

# Every record must reach the recorder: a lost one is a callback the replay cannot run.
CALLBACK_LOG_QOS = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)


def message_key(msg: object) -> tuple[int | None, int | None]:
    """(header stamp [ns] or None, CRC-32 of a ``std_msgs/String``'s text or None): what a
    `CallbackRecord` names the message taken by."""
    header = getattr(msg, 'header', None)
    stamp = Time.from_msg(header.stamp).nanoseconds if header is not None else None
    text = msg.data if isinstance(msg, String) else None
    return stamp, None if text is None else zlib.crc32(text.encode())


class GuardedCallbacks:
    """Mixin for ``rclpy.node.Node`` and ``rclpy.lifecycle.LifecycleNode``; list it first."""

    # a class attribute: Node.__init__ creates publishers before this __init__ can set it
    _noting_publisher: type[Publisher] | None = None

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.problems = ProblemReporter(self.get_logger())
        # rclpy's lifecycle services raise RCLError on a request for a transition the state
        # machine does not have (any ros2 lifecycle set typo): answered with the reason instead.
        for service in self.services:
            if service.srv_type.__module__.startswith('lifecycle_msgs'):
                service.callback = self.problems.guard_service(
                    service.srv_name, _transition_request(service.callback))
        #: Callback name (as `CallbackRecord` names it) -> (message type or None for a timer,
        #: the guarded callback).
        self.guarded_callbacks: dict[str, tuple[type | None, Callable]] = {}
        self._callback_log = None
        self._callback_time: Time | None = None
        # the running logged callback's PublishedMessage list; per thread, so that a background
        # job's publishing is no callback's
        self._logged = threading.local()
        if self.declare_parameter('callback_log', False, ParameterDescriptor(
                description='publish a record of each callback on /callback_log, for '
                'inflarm-bag-regression', read_only=True)).value:
            self._callback_log = self.create_publisher(String, CALLBACK_LOG_TOPIC,
                                                       CALLBACK_LOG_QOS)
            self._noting_publisher = _noting_publisher(self._logged)

    def create_publisher(self, *args, **kwargs) -> Publisher:
        """``Node.create_publisher``; with ``callback_log``, its messages are noted in the
        record of the callback that publishes them."""
        if self._noting_publisher is not None:
            kwargs.setdefault('publisher_class', self._noting_publisher)
        return super().create_publisher(*args, **kwargs)

    def create_guarded_subscription(self, msg_type, topic: str, callback, qos, **kwargs):
        """``create_subscription`` whose callback is guarded under the topic's name."""
        kwargs.setdefault('event_callbacks', subscription_events(self, topic))
        name = self.resolve_topic_name(topic)
        return self.create_subscription(
            msg_type, topic, self._register(name, msg_type, self.problems.guard(topic, callback)),
            qos, **kwargs)

    def create_guarded_timer(self, period_s: float, callback, name: str | None = None,
                             **kwargs):
        """``create_timer`` whose callback is guarded (problems named after ``name``)."""
        source = name or getattr(callback, '__name__', 'timer')
        guarded = self.problems.guard(source, callback)
        return self.create_timer(period_s, self._register(f'timer {source}', None, guarded),
                                 **kwargs)

    def create_guarded_service(self, srv_type, name: str, callback, **kwargs):
        """``create_service``; a rejected request is answered with the reason."""
        return self.create_service(srv_type, name, self.problems.guard_service(name, callback),
                                   **kwargs)

    def callback_time(self) -> Time:
        """The node's clock when the running guarded callback began (else now): the time its
        `CallbackRecord` gives, so an output computed from it replays exactly."""
        return self._callback_time if self._callback_time is not None else (
            self.get_clock().now())

    def _register(self, name: str, msg_type: type | None, guarded: Callable) -> Callable:
        def timed(*msg) -> Time:
            self._callback_time = started = self.get_clock().now()
            try:
                guarded(*msg)
            finally:
                self._callback_time = None
            return started

        # a lifecycle node's re-created callback replaces the one destroyed
        self.guarded_callbacks[name] = (msg_type, timed)
        if self._callback_log is None:
            return timed

        def logged(*msg) -> None:
            stamp, digest = message_key(msg[0]) if msg else (None, None)
            self._logged.published = published = []
            try:
                started = timed(*msg)
            finally:
                self._logged.published = None
            self._callback_log.publish(to_string_msg(CallbackRecord(
                self.get_fully_qualified_name(), name, started.nanoseconds, stamp, digest,
                tuple(published))))
        return logged


def _noting_publisher(logged: threading.local) -> type[Publisher]:
    """A ``Publisher`` class that notes each message it publishes (with a stamp or a text) in
    ``logged.published`` while that is a list."""
    class NotingPublisher(Publisher):
        def publish(self, msg) -> None:
            super().publish(msg)
            published = getattr(logged, 'published', None)
            if published is not None and (key := message_key(msg)) != (None, None):
                published.append(PublishedMessage(self.topic_name, *key))
    return NotingPublisher


def _transition_request(callback):
    """A lifecycle service callback whose unknown transition is a rejected request."""
    @functools.wraps(callback)
    def call(request, response):
        try:
            return callback(request, response)
        except _rclpy.RCLError as error:
            raise ValueError(str(error).split(', at ')[0]) from error
    return call
