"""JSON messages carried in std_msgs/String, and the node conventions shared by the inflarm nodes.

The messages are pure Python (stdlib only): importing this package never imports rclpy; the ROS
side lives in the ``inflarm_msgs_json.ros`` subpackage.

>>> from inflarm_msgs_json import PlanRequest, decode, encode
>>> request = PlanRequest('base_link', start=(0, 0, 0.3), goal=(0.2, 0.1, 0.3), resolution=0.01)
>>> decode(encode(request), expected=PlanRequest) == request
True
"""

from inflarm_msgs_json.codec import decode, encode
from inflarm_msgs_json.messages import (
    CALLBACK_LOG_TOPIC,
    VACUUM_GAUGE_PA,
    CallbackRecord,
    ChamberPressures,
    ControlTask,
    Cuboid,
    HardwareStatus,
    LinkPressures,
    LinkStatus,
    ObstacleSet,
    PlanOutcome,
    PlanRequest,
    PressureCommand,
    PublishedMessage,
    TrialReport,
)
from inflarm_msgs_json.spec import MESSAGE_TYPES, Message, MessageError, json_schema

__all__ = [
    'CALLBACK_LOG_TOPIC',
    'MESSAGE_TYPES',
    'VACUUM_GAUGE_PA',
    'CallbackRecord',
    'ChamberPressures',
    'ControlTask',
    'Cuboid',
    'HardwareStatus',
    'LinkPressures',
    'LinkStatus',
    'Message',
    'MessageError',
    'ObstacleSet',
    'PlanOutcome',
    'PlanRequest',
    'PressureCommand',
    'PublishedMessage',
    'TrialReport',
    'decode',
    'encode',
    'json_schema',
]
