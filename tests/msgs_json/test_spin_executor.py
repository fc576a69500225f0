"""The executor of every node process (``INFLARM_EXECUTOR``, `spin_node`): with each one a node
receives messages, publishes from its callbacks and timers, and stops on SIGINT and SIGTERM
with exit code 0; an unknown name is refused at start. The scheduling of every node process
(``INFLARM_REALTIME_PRIORITY``): all its threads under SCHED_FIFO at the priority named, or
a warning saying why not."""

import contextlib
import os
import signal
import subprocess
import sys
import time

import pytest

from inflarm_bringup.processes import NodeProcess, ros_environment
from inflarm_msgs_json.ros.spin import (
    DEFAULT_EXECUTOR,
    EXECUTORS,
    executor_kind,
    realtime_priority,
)

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


def entry_point_command(tmp_path, module: str, source: str) -> list[str]:
    """``node_entry(module)`` in a fresh interpreter, ``module`` written from ``source``."""
    (tmp_path / f'{module}.py').write_text(source)
    code = ('import sys; sys.path.insert(0, sys.argv[1]); '
            f'from inflarm_msgs_json.ros.signals import node_entry; node_entry("{module}")()')
    return [sys.executable, '-c', code, str(tmp_path)]


def start_entry_point(tmp_path, module: str, source: str, **env) -> subprocess.Popen:
    return subprocess.Popen(entry_point_command(tmp_path, module, source),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, **env))


@contextlib.contextmanager
def running(command: list[str], env: dict[str, str], err_path):
    """The process of ``command`` (its stderr into ``err_path``), stopped with SIGINT after
    the block (killed if the block fails or it does not exit within 20 s)."""
    with open(err_path, 'w') as err_file:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err_file, env=env)
    try:
        yield process
        process.send_signal(signal.SIGINT)
        process.wait(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


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


def test_the_realtime_priority_comes_from_the_environment():
    assert realtime_priority({}) == 0
    assert realtime_priority({}, default=50) == 50  # a node's own default
    assert realtime_priority({'INFLARM_REALTIME_PRIORITY': '0'}, default=50) == 0
    assert realtime_priority({'INFLARM_REALTIME_PRIORITY': ' 7 '}) == 7
    assert realtime_priority({'INFLARM_REALTIME_PRIORITY': ''}, default=50) == 50
    for bad in ('100', '-1', 'high', '5.5'):
        with pytest.raises(ValueError, match='INFLARM_REALTIME_PRIORITY'):
            realtime_priority({'INFLARM_REALTIME_PRIORITY': bad})


def may_take_realtime_priority() -> bool:
    """Whether a process of this user may schedule itself SCHED_FIFO (root, or an rtprio
    limit): what a node process is to do depends on it."""
    probe = 'import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))'
    return subprocess.run([sys.executable, '-c', probe], capture_output=True).returncode == 0


def thread_scheduling(pid: int) -> set[tuple[int, int]]:
    """(policy, priority) of every thread of process ``pid``."""
    found = set()
    for tid in map(int, os.listdir(f'/proc/{pid}/task')):
        with contextlib.suppress(ProcessLookupError):  # ended meanwhile
            found.add((os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority))
    return found


def scheduled_as(process: subprocess.Popen, expected: set, err_path, timeout_s: float = 30.0):
    """The scheduling of the node process's threads once they all have ``expected``, or once
    its log says it could not take a real-time priority, or after ``timeout_s`` (None if it
    exited)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and process.poll() is None:
        if thread_scheduling(process.pid) == expected:
            return expected
        if 'real-time priority' in err_path.read_text():
            break  # refused, and said so
        time.sleep(0.1)
    return thread_scheduling(process.pid) if process.poll() is None else None


@pytest.mark.parametrize('priority', [0, 7])
def test_every_thread_of_a_node_process_runs_at_the_priority_named(tmp_path, domain_id,
                                                                   priority):
    err_path = tmp_path / 'err.txt'
    env = dict(os.environ, INFLARM_REALTIME_PRIORITY=str(priority), ROS_DOMAIN_ID=str(domain_id))
    with running(entry_point_command(tmp_path, 'echo_node', ECHO_NODE), env,
                 err_path) as process:
        if priority == 0:
            time.sleep(3.0)  # built and spinning: nothing is to change meanwhile
            assert thread_scheduling(process.pid) == {(os.SCHED_OTHER, 0)}
        elif may_take_realtime_priority():
            assert scheduled_as(process, {(os.SCHED_FIFO, priority)}, err_path) \
                == {(os.SCHED_FIFO, priority)}, err_path.read_text()
        else:
            assert scheduled_as(process, {(os.SCHED_FIFO, priority)}, err_path) \
                == {(os.SCHED_OTHER, 0)}
    err = err_path.read_text()
    assert process.returncode == 0, err
    if priority and not may_take_realtime_priority():
        assert f'cannot take real-time priority {priority} (SCHED_FIFO)' in err, err


def test_the_load_estimator_takes_priority_50_by_default_and_says_so(tmp_path, ros_context,
                                                                    domain_id):
    """The node fed at 1 kHz: under SCHED_FIFO so that other jobs on the machine cannot keep
    it from its samples (the estimation README has the runs with two busy processes); its
    diagnostics name the scheduling it got."""
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    env = ros_environment(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    env.pop('INFLARM_REALTIME_PRIORITY', None)
    err_path = tmp_path / 'err.txt'
    node = rclpy.create_node('probe', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    reports = []
    node.create_subscription(DiagnosticArray, 'diagnostics', reports.append, 10)
    with running(NodeProcess('inflarm_estimation', 'load_estimator').command(), env,
                 err_path) as process:
        permitted = may_take_realtime_priority()
        expected = {(os.SCHED_FIFO, 50)} if permitted else {(os.SCHED_OTHER, 0)}
        assert scheduled_as(process, {(os.SCHED_FIFO, 50)}, err_path, timeout_s=60.0) \
            == expected, err_path.read_text()
        deadline = time.monotonic() + 30.0
        while not reports and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert reports, 'no diagnostics from load_estimator within 30 s'
        values = {kv.key: kv.value for kv in reports[-1].status[0].values}
        assert values['scheduling'] == ('SCHED_FIFO 50' if permitted else 'SCHED_OTHER')
    executor.shutdown()
    node.destroy_node()
    assert process.returncode == 0, err_path.read_text()


def test_a_bad_realtime_priority_is_refused_at_start(tmp_path, domain_id):
    process = start_entry_point(tmp_path, 'echo_node', ECHO_NODE,
                                INFLARM_REALTIME_PRIORITY='urgent', ROS_DOMAIN_ID=str(domain_id))
    _, err = process.communicate(timeout=40)
    assert process.returncode == 1
    assert 'INFLARM_REALTIME_PRIORITY' in err and "'urgent'" in err and 'Traceback' not in err
