"""Replays a rosbag2 bag (sqlite3 or MCAP): ``ros2 bag play`` for this workspace.

Every recorded message goes out as its stored CDR bytes, unchanged (headers keep their recorded
stamps), on its original topic with its original type. The recorded spacing of the messages is
kept, divided by ``rate``, on a steady-clock schedule: one timer, re-armed for the next message
due, publishes every message whose time has come, so a late tick catches up instead of
drifting. At the end the player logs a summary and idles, or with ``loop`` starts again.

Publishes:
    each recorded topic (or those in ``topics``) with its recorded type: REPLAY_QOS, or
    LATCHED_REPLAY_QOS where every recorded publisher of the topic was transient-local.
    /clock (rosgraph_msgs/Clock), when ``clock_rate_hz`` > 0: the bag time being played, so
    that nodes run with ``use_sim_time`` follow the recording's time (``ros2 bag play --clock``).
Parameters:
    input (string, read-only): bag directory to replay; required.
    rate (double, 0.001-1000): playback speed (2.0 plays twice as fast); may change at runtime.
    loop (bool): start again after the last message; may change at runtime.
    topics (string[], read-only): topics to replay (names as in the bag; relative names are in
        the root namespace); unset: all of them.
    start_delay_s (double, read-only): wait this long before the first message, so that
        subscribers discover the player's publishers and miss nothing.
    clock_rate_hz (double, read-only): rate of /clock [Hz]; 0: no /clock.
"""

import time

from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock

from inflarm_hw.bag import BagMessage, TopicInfo, bag_info, read_messages, select_topics
from inflarm_hw.nodes.bag_recorder import message_class
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import publisher_events
from inflarm_msgs_json.ros.spin import spin_node

# Reliable is offered: it matches reliable and best-effort subscribers alike, and reliable ones
# (estimates, reports) then get every message, as they would from a reliable live publisher.
# Depth 1000 keeps a burst (rate > 1, or catching up after a stall) from overwriting messages
# before reliable subscribers have acknowledged them. Matching the recorded QoS instead would
# keep best-effort topics lossy for no gain; only durability is taken from the recording.
REPLAY_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
# Latched topics (robot description, paths) stay latched: a volatile publisher is incompatible
# with the transient-local subscribers that wait for them, and late joiners need the last one.
LATCHED_REPLAY_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL,
                                history=HistoryPolicy.KEEP_LAST)
MIN_TICK_NS = 100_000  # 0.1 ms: the timer's shortest re-arm
MAX_BURST_NS = 20_000_000  # a tick that catches up returns to the executor after 20 ms
MAX_TICK_NS = 500_000_000  # idle ticks at least every 0.5 s

PARAMETERS = (
    Parameter('input', '', 'bag directory to replay (required)', read_only=True),
    Parameter('rate', 1.0, 'playback speed, 2.0 plays twice as fast', range=(0.001, 1000.0)),
    Parameter('loop', False, 'start again after the last message'),
    # A string array without a default: rclpy would type an empty list as a byte array.
    Parameter('topics', RosParameter.Type.STRING_ARRAY, 'topics to replay; unset: all',
              read_only=True),
    Parameter('start_delay_s', 1.0, 'wait before the first message, for discovery [s]',
              range=(0.0, 3600.0), read_only=True),
    Parameter('clock_rate_hz', 0.0, 'rate of /clock with the bag time [Hz]; 0: no /clock',
              range=(0.0, 1000.0), read_only=True),
)
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST)


def replay_qos(topic: TopicInfo) -> QoSProfile:
    """LATCHED_REPLAY_QOS when every recorded publisher was transient-local, else REPLAY_QOS."""
    latched = bool(topic.offered_qos) and all(
        q.durability == 'transient_local' for q in topic.offered_qos)
    return LATCHED_REPLAY_QOS if latched else REPLAY_QOS


class BagPlayer(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('bag_player', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS, on_set=self.on_parameters_set)
        if not p['input']:
            raise ValueError("parameter 'input' is required: the bag directory to replay, e.g. "
                             '-p input:=run1')
        self.info = bag_info(p['input'])  # a clear ValueError for a missing or broken bag
        self.topics = select_topics(self.info, p['topics'] or None)
        self.topic_pubs = {}
        for topic in self.topics:
            msg_class = message_class(self.info.topics[topic].msgtype)
            self.topic_pubs[topic] = self.create_publisher(
                msg_class, topic, replay_qos(self.info.topics[topic]),
                event_callbacks=publisher_events(self, topic))
        self.total = sum(self.info.topics[t].message_count for t in self.topics)

        self.messages = None  # the current pass through the bag
        self.pending: BagMessage | None = None  # its next message
        self.bag_origin_ns = 0  # bag time that plays at wall_origin_ns
        self.wall_origin_ns = 0  # steady clock [ns]
        self.rate = p['rate']  # the schedule's rate since wall_origin_ns
        self.pass_start_ns = 0
        self.passes = 0
        self.played = 0
        self.done = False
        self.timer = self.create_guarded_timer(max(p['start_delay_s'], MIN_TICK_NS * 1e-9),
                                               self.tick)
        self.clock_pub = None
        if p['clock_rate_hz'] > 0.0:
            self.clock_pub = self.create_publisher(Clock, '/clock', CLOCK_QOS)
            self.create_guarded_timer(1.0 / p['clock_rate_hz'], self.publish_clock)
        self.get_logger().info(
            f'ready: {self.total} messages on {self.topics} from {self.info.path} at rate '
            f"{p['rate']}, starting in {p['start_delay_s']} s")

    def on_parameters_set(self, changed: dict) -> None:
        if 'rate' in changed:
            playing = self.pending is not None
            if playing:
                # Rebase the schedule where playback is now, so the speed changes from here on.
                now = time.monotonic_ns()
                self.bag_origin_ns += round((now - self.wall_origin_ns) * self.rate)
                self.wall_origin_ns = now
            self.rate = changed['rate']
            if playing:
                self.rearm(self.due_ns(self.pending) - now)
        if changed.get('loop') and self.done:
            self.done = False
            self.rearm(0)
        for name, value in changed.items():
            self.get_logger().info(f'{name} now {value}')

    def bag_time_ns(self) -> int:
        """The bag time playing now: before the first message its time, after the last the
        last one's."""
        if self.passes == 0:
            return self.info.start_ns
        if self.pending is None:
            return self.info.start_ns + self.info.duration_ns
        now = time.monotonic_ns()
        return min(self.bag_origin_ns + round((now - self.wall_origin_ns) * self.rate),
                   self.pending.timestamp_ns)

    def publish_clock(self) -> None:
        self.clock_pub.publish(Clock(clock=Time(nanoseconds=self.bag_time_ns()).to_msg()))

    def due_ns(self, message: BagMessage) -> int:
        return self.wall_origin_ns + round(
            (message.timestamp_ns - self.bag_origin_ns) / self.rate)

    def rearm(self, delay_ns: int) -> None:
        self.timer.timer_period_ns = min(max(delay_ns, MIN_TICK_NS), MAX_TICK_NS)
        self.timer.reset()

    def start_pass(self) -> None:
        self.messages = read_messages(self.info.path, self.topics)
        self.pending = next(self.messages, None)
        now = time.monotonic_ns()
        self.bag_origin_ns = self.pending.timestamp_ns if self.pending else 0
        self.wall_origin_ns = self.pass_start_ns = now
        self.played = 0
        self.passes += 1
        if self.passes == 1:
            self.get_logger().info(f'playing {self.info.path}')

    def tick(self) -> None:
        if self.done:
            self.timer.cancel()
            return
        if self.pending is None:
            self.start_pass()
        now = time.monotonic_ns()
        while self.pending is not None and self.due_ns(self.pending) <= now:
            self.topic_pubs[self.pending.topic].publish(self.pending.data)
            self.played += 1
            self.pending = next(self.messages, None)
            if time.monotonic_ns() - now > MAX_BURST_NS:
                break  # let the executor run (other callbacks, a stop request) in between
        if self.pending is not None:
            self.rearm(self.due_ns(self.pending) - time.monotonic_ns())
            return
        self.finish_pass()

    def finish_pass(self) -> None:
        self.messages = None
        elapsed = (time.monotonic_ns() - self.pass_start_ns) * 1e-9
        self.get_logger().info(
            f'done: played {self.played} messages in {elapsed:.2f} s '
            f'(recorded over {self.info.duration_ns * 1e-9:.2f} s, rate {self.params["rate"]})'
            + (f', pass {self.passes}' if self.params['loop'] or self.passes > 1 else ''))
        if self.played == 0:
            self.get_logger().warning('nothing to play: the selected topics have no messages')
        if self.params['loop'] and self.played > 0:
            self.rearm(0)
        else:
            self.done = True
            self.timer.cancel()

    def destroy_node(self) -> None:
        if self.messages is not None:
            self.messages.close()  # closes the bag
            self.messages = None
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(BagPlayer, args)


if __name__ == '__main__':
    main()
