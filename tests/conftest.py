"""Shared fixtures: in-process rclpy contexts and node executables as real processes.

Every test gets its own ROS_DOMAIN_ID; DDS stays on loopback with fast discovery announcements
(inflarm_bringup/config/fastdds_profile.xml). Waits are bounded waits on data, never fixed sleeps.
"""

import fcntl
import os
import pathlib
import sys
import tempfile

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / 'tests'))

from inflarm_bringup.processes import ros_environment  # noqa: E402

# Before rclpy is imported anywhere: the same DDS environment as the launched processes.
os.environ.update(ros_environment())

from ros_harness import NodeProcesses  # noqa: E402

# ROS domain ids 1-100 are taken under a file lock for the length of a test, so that test runs
# going on at the same time on this machine (other checkouts, CI) never share a domain.
DOMAIN_LOCKS = pathlib.Path(tempfile.gettempdir()) / 'inflarm-ros-domains'
_next_domain = os.getpid() % 100


def lock_free_domain():
    """(domain id, open lock file) for the first domain no other process holds."""
    global _next_domain
    DOMAIN_LOCKS.mkdir(exist_ok=True)
    for _ in range(100):
        candidate = _next_domain % 100 + 1
        _next_domain += 1
        lock = open(DOMAIN_LOCKS / f'{candidate}.lock', 'w')  # noqa: SIM115 (held by the test)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        return candidate, lock
    raise RuntimeError(f'every ROS domain 1-100 is in use by other test runs ({DOMAIN_LOCKS})')


@pytest.fixture
def domain_id():
    """A ROS domain id that no other test, in this run or any other, uses meanwhile."""
    domain, lock = lock_free_domain()
    yield domain
    lock.close()  # releases the lock


@pytest.fixture
def ros_context(domain_id):
    """An initialized rclpy context on this test's domain; shut down afterwards."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def executor(ros_context):
    """A single-threaded executor on ``ros_context``; nodes added to it are destroyed after."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros_context)
    yield executor
    for node in executor.get_nodes():
        executor.remove_node(node)
        node.destroy_node()
    executor.shutdown()


@pytest.fixture
def node_processes(domain_id, tmp_path):
    """Start node executables as real processes on this test's domain.

    At teardown every process gets SIGINT and must exit with code 0.
    """
    processes = NodeProcesses(domain_id, tmp_path)
    yield processes
    codes = processes.stop()
    assert all(code == 0 for code in codes.values()), (
        f'unclean exit codes {codes}; output:\n{processes.output()}')
