"""The test harness's own logic that the system tests rest on."""

from geometry_msgs.msg import WrenchStamped
import numpy as np
from sensor_msgs.msg import JointState

from ros_harness import BaseFrameForces


class _Subscriptions:
    """Stands in for a node: keeps each subscription's callback by topic."""

    def __init__(self) -> None:
        self.callbacks = {}

    def create_subscription(self, _type, topic, callback, _qos):
        self.callbacks[topic] = callback


def _stamped(message, t_ns: int):
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(t_ns, 10 ** 9)
    return message


def test_base_frame_forces_pair_on_past_a_message_lost_on_one_topic():
    node = _Subscriptions()
    forces = BaseFrameForces(node)
    q = [0.0] * 7

    def send(t_ns: int, pose: bool = True, wrench: bool = True) -> None:
        if wrench:
            msg = _stamped(WrenchStamped(), t_ns)
            msg.wrench.force.z = -1.0
            node.callbacks['estimated_wrench'](msg)
        if pose:
            node.callbacks['estimated_joint_states'](_stamped(JointState(position=q), t_ns))

    send(10, pose=False)  # its pose sent before the subscription matched
    send(20, wrench=False)  # its wrench lost
    for t_ns in range(30, 80, 10):
        send(t_ns)
    assert [round(t * 1e9) for t, _ in forces.forces] == [30, 40, 50, 60, 70]
    rotation = forces.arm.fk(q)[:3, :3]
    np.testing.assert_allclose(forces.forces[-1][1], rotation @ [0.0, 0.0, -1.0])
    assert not forces.wrenches and not forces.poses
