"""The executor of every node process (``INFLARM_EXECUTOR``, `spin_node`): with each one a node
receives messages, publishes from its callbacks and timers, and stops on SIGINT and SIGTERM
with exit code 0; an unknown name is refused at start."""

import os
import signal
import subprocess
import sys
import time

import pytest

from inflarm_msgs_json.ros.spin import DEFAULT_EXECUTOR, EXECUTORS, executor_kind

pytestmark = pytest.mark.system  # node entry points in processes of their own

# A node that echoes every `chatter` message on `echo` and counts its timer on `ticks`.
ECHO_NODE = """
from rclpy.node import Node
from std_msgs.msg import Int32
from inflarm_msgs_json.ros.spin import spin_node
class Echo(Node):
    def __init__(self):
        super().__init__('echo')
        self.echo = self.create_publisher(Int32, 'echo', 1000)
        self.ticks = self.create_publisher(Int32, 'ticks', 10)
        self.count = 0
        self.create_subscription(Int32, 'chatter', self.echo.publish, 1000)
        self.create_timer(0.02, self.tick)
    def tick(self):
        self.count += 1
        self.ticks.publish(Int32(data=self.count))
def main():
    spin_node(Echo, [])
"""


def start_entry_point(tmp_path, module: str, source: str, **env) -> subprocess.Popen:
    """Start ``node_entry(module)`` in a fresh interpreter, ``module`` written from ``source``."""
    (tmp_path / f'{module}.py').write_text(source)
    code = ('import sys; sys.path.insert(0, sys.argv[1]); '
            f'from inflarm_msgs_json.ros.signals import node_entry; node_entry("{module}")()')
    return subprocess.Popen([sys.executable, '-c', code, str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, **env))


def test_the_executor_name_comes_from_the_environment():
    assert executor_kind({}) == DEFAULT_EXECUTOR == 'single_threaded'
    assert executor_kind({}, default='events') == 'events'  # a node's own default
    assert executor_kind({'INFLARM_EXECUTOR': 'single_threaded'}, default='events') \
        == 'single_threaded'
    assert executor_kind({'INFLARM_EXECUTOR': ' single_threaded '}) == 'single_threaded'
    assert executor_kind({'INFLARM_EXECUTOR': 'events'}) == 'events'
    with pytest.raises(ValueError, match='INFLARM_EXECUTOR'):
        executor_kind({'INFLARM_EXECUTOR': 'multi'})


@pytest.mark.parametrize('kind', sorted(EXECUTORS))
@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM])
def test_a_node_on_each_executor_receives_publishes_and_stops(tmp_path, ros_context, domain_id,
                                                              kind, stop):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Int32

    process = start_entry_point(tmp_path, 'echo_node', ECHO_NODE, INFLARM_EXECUTOR=kind,
                                ROS_DOMAIN_ID=str(domain_id))
    node = rclpy.create_node('probe', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    echoed, ticks = set(), []
    node.create_subscription(Int32, 'echo', lambda m: echoed.add(m.data), 1000)
    node.create_subscription(Int32, 'ticks', lambda m: ticks.append(m.data), 10)
    chatter = node.create_publisher(Int32, 'chatter', 1000)
    try:
        deadline = time.monotonic() + 20.0
        while (chatter.get_subscription_count() == 0 or not ticks) \
                and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert ticks, 'no timer message from the node within 20 s'
        while -1 not in echoed and time.monotonic() < deadline:  # both directions matched
            chatter.publish(Int32(data=-1))
            spin_until = time.monotonic() + 0.1
            while time.monotonic() < spin_until:
                executor.spin_once(timeout_sec=0.02)
        assert -1 in echoed, 'nothing echoed within 20 s'
        echoed.clear()
        for i in range(200):
            chatter.publish(Int32(data=i))
            executor.spin_once(timeout_sec=0.0)
        deadline = time.monotonic() + 10.0
        while len(echoed) < 200 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert echoed - {-1} == set(range(200))
        process.send_signal(stop)
        out, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        executor.shutdown()
        node.destroy_node()
    assert process.returncode == 0, err
    assert 'Traceback' not in err and 'RCLError' not in err, err


def test_an_unknown_executor_is_refused_at_start(tmp_path, domain_id):
    process = start_entry_point(tmp_path, 'echo_node', ECHO_NODE, INFLARM_EXECUTOR='fast',
                                ROS_DOMAIN_ID=str(domain_id))
    _, err = process.communicate(timeout=40)
    assert process.returncode == 1
    assert 'INFLARM_EXECUTOR' in err and 'Traceback' not in err, err
