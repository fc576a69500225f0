"""Helpers for tests that talk to nodes over real DDS: bounded waits and node processes."""

from collections.abc import Callable
import io
import os
import pathlib
import threading
import time

from inflarm_launch import NodeProcess, ProcessGroup


def spin_until(executor, predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    """Spin ``executor`` until ``predicate()`` holds or ``timeout_s`` passes; return it."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def wait_until(predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    """Poll ``predicate()`` (no ROS spinning) until it holds or ``timeout_s`` passes."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


class _SyncBuffer(io.StringIO):
    """A StringIO that the relay threads and the test can use at the same time."""

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()

    def write(self, text: str) -> int:
        with self._lock:
            return super().write(text)

    def getvalue(self) -> str:
        with self._lock:
            return super().getvalue()


class NodeProcesses:
    """Node executables run as real processes on one ROS domain, their output collected."""

    def __init__(self, domain_id: int, workdir: pathlib.Path) -> None:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_LOG_DIR=str(workdir / 'ros_log'))
        self._buffer = _SyncBuffer()
        self.group = ProcessGroup(env, output=self._buffer)

    def start(self, package: str, executable: str, *ros_args: str,
              parameters: dict | None = None, name: str | None = None):
        """Start ``executable`` with its installed config, ``parameters`` and extra ros args."""
        node = NodeProcess(package, executable, parameters or {})
        command = node.command() + list(ros_args)
        return self.group.start(name or executable, command)

    def output(self) -> str:
        return self._buffer.getvalue()

    def wait_for_output(self, text: str, timeout_s: float = 15.0) -> bool:
        return wait_until(lambda: text in self.output(), timeout_s)

    def stop(self) -> dict[str, int]:
        return self.group.stop()
