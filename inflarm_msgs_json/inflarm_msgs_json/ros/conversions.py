"""inflarm JSON messages to and from ``std_msgs/String``, the carrier on every JSON topic."""

from std_msgs.msg import String

from inflarm_msgs_json import decode, encode


def to_string_msg(message) -> String:
    """Wrap an inflarm JSON message in a ``std_msgs/String``."""
    return String(data=encode(message))


def from_string_msg(msg: String, expected: type | None = None):
    """Decode the message in ``msg.data``; raises ``MessageError`` naming what was wrong."""
    return decode(msg.data, expected=expected)
