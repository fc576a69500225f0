"""The QoS event callbacks every guarded subscription gets."""

import pytest
import rclpy
from rclpy.event_handler import QoSSubscriptionEventType
from std_msgs.msg import String

from inflarm_msgs_json.ros.qos import RELIABLE_QOS, subscription_events


def test_a_message_lost_callback_is_refused_with_the_reason(executor):
    node = rclpy.create_node('qos_events', context=executor.context)
    with pytest.raises(ValueError, match='message_lost.*rmw_fastrtps#890'):
        subscription_events(node, 'joint_states', message_lost=lambda event: None)
    matched = subscription_events(node, 'joint_states', matched=lambda event: None)
    subscription = node.create_subscription(String, 'joint_states', lambda msg: None,
                                            RELIABLE_QOS, event_callbacks=matched)
    assert {h.event_type for h in subscription.event_handlers} >= {
        QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS,
        QoSSubscriptionEventType.RCL_SUBSCRIPTION_MATCHED}
    node.destroy_node()
