"""What the bag regression knows of a node under test: its topics, read off the node
(`inflarm_bringup.ros.lockstep`), and the topics that are neither inputs nor outputs or that
are replayed but not compared (`inflarm_bringup.bag_regression`)."""

from collections.abc import Mapping
from dataclasses import dataclass

from inflarm_msgs_json import CALLBACK_LOG_TOPIC

__all__ = ['INFRASTRUCTURE_TOPICS', 'NOT_COMPARED', 'NodeIo']

#: Topics of the ROS plumbing: neither inputs nor outputs of a node under test.
INFRASTRUCTURE_TOPICS = frozenset({CALLBACK_LOG_TOPIC, '/clock', '/parameter_events', '/rosout'})
#: Outputs replayed but not compared: counts since the last report, which depend on where the
#: reports fell in the recording.
NOT_COMPARED = frozenset({'/diagnostics'})


@dataclass(frozen=True)
class NodeIo:
    """A node's topics, read off the node: ``{topic: msgtype}`` in and out."""

    name: str
    inputs: Mapping[str, str]
    outputs: Mapping[str, str]

    @property
    def compared_outputs(self) -> list[str]:
        return sorted(t for t in self.outputs if t not in NOT_COMPARED)
