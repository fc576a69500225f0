"""Shared fixtures: in-process rclpy contexts and node executables as real processes.

Every test gets its own ROS_DOMAIN_ID; DDS stays on loopback with fast discovery announcements
(inflarm_bringup/config/fastdds_profile.xml). Waits are bounded waits on data, never fixed sleeps.
"""

import os
import pathlib
import sys

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / 'tests'))

from inflarm_bringup.processes import ros_environment  # noqa: E402

# Before rclpy is imported anywhere: the same DDS environment as the launched processes.
os.environ.update(ros_environment())

from ros_harness import NodeProcesses, lock_free_domain  # noqa: E402


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """A test that starts node executables (``node_processes``) is a system test, marked or not:
    the fast lane (``-m 'not system'``) then leaves it out."""
    for item in items:
        if 'node_processes' in getattr(item, 'fixturenames', ()):
            item.add_marker(pytest.mark.system)


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
