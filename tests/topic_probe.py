"""A node that writes what it receives on some topics to a JSON-lines file: a test's eyes on a
host that the test's own rclpy context cannot reach (another network namespace).

Started as a process by `probe_command`, through the same entry point as every inflarm node
(``inflarm_msgs_json.ros.signals.node_entry``: the stop signals are owned from the start, and
SIGINT ends it with exit code 0). Each received message is one line, flushed at once::

    {"topic": "trial_report", "t": 12.5, "data": "<the String's text>"}
    {"topic": "end_point_truth", "t": 12.6, "frame_id": "sra_mount", "point": [x, y, z]}

``t`` is the receive time on the monotonic clock [s]. `read_records` reads them back.

Subscribes:
    ``string_topics`` (std_msgs/String, RELIABLE_QOS), ``point_topics``
    (geometry_msgs/PointStamped, SENSOR_QOS).
Parameters:
    output (string, read-only): the file, appended to.
    string_topics, point_topics (string[], read-only): the topics.
"""

import json
import pathlib
import sys
import time

from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from std_msgs.msg import String

from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from inflarm_msgs_json.ros.spin import spin_node

TESTS_DIR = pathlib.Path(__file__).resolve().parent

PARAMETERS = (
    Parameter('output', '', 'JSON-lines file the messages are appended to (required)',
              read_only=True),
    # Typed without a default: rclpy would type an empty list as a byte array.
    Parameter('string_topics', RosParameter.Type.STRING_ARRAY, 'std_msgs/String topics',
              read_only=True),
    Parameter('point_topics', RosParameter.Type.STRING_ARRAY, 'geometry_msgs/PointStamped topics',
              read_only=True),
)


class TopicProbe(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('topic_probe', **kwargs)
        p = declare_parameters(self, PARAMETERS)
        if not p['output']:
            raise ValueError("parameter 'output' is required: the file to write")
        string_topics, point_topics = p['string_topics'] or [], p['point_topics'] or []
        if not string_topics and not point_topics:
            raise ValueError("expected topics in 'string_topics' or 'point_topics', got none")
        self.file = open(p['output'], 'a', encoding='utf-8')  # noqa: SIM115 (closed on destroy)
        for topic in string_topics:
            self.create_guarded_subscription(
                String, topic, lambda msg, topic=topic: self.write(topic, data=msg.data),
                RELIABLE_QOS)
        for topic in point_topics:
            self.create_guarded_subscription(
                PointStamped, topic, lambda msg, topic=topic: self.write(
                    topic, frame_id=msg.header.frame_id,
                    point=[msg.point.x, msg.point.y, msg.point.z]),
                SENSOR_QOS)
        self.get_logger().info(f'ready: writing {string_topics + point_topics} to {p["output"]}')

    def write(self, topic: str, **fields) -> None:
        self.file.write(json.dumps({'topic': topic, 't': time.monotonic(), **fields}) + '\n')
        self.file.flush()

    def destroy_node(self) -> None:
        super().destroy_node()
        self.file.close()


def main(args: list[str] | None = None) -> None:
    spin_node(TopicProbe, args)


def probe_command(output: pathlib.Path, string_topics: list[str] = (),
                  point_topics: list[str] = ()) -> list[str]:
    """The command line of a probe writing ``string_topics`` and ``point_topics`` to ``output``."""
    entry = (f'import sys; sys.path.insert(0, {str(TESTS_DIR)!r}); '
             'from inflarm_msgs_json.ros.signals import node_entry; node_entry("topic_probe")()')
    command = [sys.executable, '-c', entry, '--ros-args', '-p', f'output:={output}']
    for name, topics in (('string_topics', string_topics), ('point_topics', point_topics)):
        if topics:
            command += ['-p', f"{name}:=[{', '.join(topics)}]"]
    return command


def read_records(path: pathlib.Path, topic: str | None = None) -> list[dict]:
    """The records in ``path`` so far (of ``topic`` only, if given), in order received."""
    try:
        text = pathlib.Path(path).read_text(encoding='utf-8')
    except FileNotFoundError:
        return []
    records = [json.loads(line) for line in text.splitlines(keepends=True)
               if line.endswith('\n')]  # a line being written is read next time
    return [r for r in records if topic is None or r['topic'] == topic]
