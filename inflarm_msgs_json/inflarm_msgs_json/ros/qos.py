"""QoS profiles named by meaning, and event callbacks that make QoS mismatches visible."""

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

# High-rate sensor streams where the newest sample is all that matters (images, ball positions,
# simulated ground truth): best effort, so a slow subscriber never holds the publisher up.
SENSOR_QOS = qos_profile_sensor_data
# joint_states as ros2_control's joint_state_broadcaster publishes it and robot_state_publisher
# subscribes to it: reliable, volatile, the last 10.
JOINT_STATE_QOS = QoSProfile(
    depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
# Commands: reliable, only the newest is worth executing.
COMMAND_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
# Results and reports that must all arrive (trial reports, estimates, diagnostics).
RELIABLE_QOS = QoSProfile(
    depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
# State that late joiners need (robot description, paths, obstacles).
LATCHED_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def subscription_events(node: Node, topic: str, **callbacks) -> SubscriptionEventCallbacks:
    """Callbacks logging an incompatible publisher, which otherwise drops data silently; other
    event callbacks (e.g. ``matched``) may be added, but not ``message_lost``.

    rmw_fastrtps 8.4 (Jazzy) takes a message-lost event under its event mutex and then the
    reader's, while a DDS thread reporting a new loss holds them the other way round: under
    steady losses the node deadlocks in ``take_event`` (ros2/rmw_fastrtps#890; it hung
    ``load_estimator`` at 1 kHz). A match is reported without the reader's mutex held: that
    event is safe (the main README, "Launching systems")."""
    if 'message_lost' in callbacks:
        raise ValueError(f"subscription '{topic}': no message_lost callback: rmw_fastrtps 8.4 "
                         'can deadlock taking that event (ros2/rmw_fastrtps#890)')

    def on_incompatible(event) -> None:
        node.get_logger().error(
            f"subscription '{topic}': incompatible QoS offered by a publisher "
            f'(policy {event.last_policy_kind}); no data will flow'
        )
    return SubscriptionEventCallbacks(incompatible_qos=on_incompatible, **callbacks)


def publisher_events(node: Node, topic: str) -> PublisherEventCallbacks:
    """Callbacks logging an incompatible subscriber, which otherwise receives nothing."""
    def on_incompatible(event) -> None:
        node.get_logger().error(
            f"publisher '{topic}': incompatible QoS requested by a subscriber "
            f'(policy {event.last_policy_kind}); it will receive nothing'
        )
    return PublisherEventCallbacks(incompatible_qos=on_incompatible)
