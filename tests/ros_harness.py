"""Helpers for tests that talk to nodes over real DDS: bounded waits and node processes."""

from collections.abc import Callable
import fcntl
import io
import os
import pathlib
import tempfile
import threading
import time

from inflarm_bringup.processes import NodeProcess, ProcessGroup

# ROS domain ids 1-100 are taken under a file lock for the length of a test (or of a module's
# fixture), so that test runs
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


class BaseFrameForces:
    """Estimated tip forces in the base frame, from ``estimated_wrench`` (tip frame) and the
    ``estimated_joint_states`` of the same stamp, as a tf2 user would turn them.

    Either topic may lose a message the other has (its subscription matched later, or a
    reader queue overran on a loaded machine): such a message is dropped once a newer stamp
    has been paired, since the stamps only grow."""

    def __init__(self, node, arm=None) -> None:
        from geometry_msgs.msg import WrenchStamped
        from sensor_msgs.msg import JointState

        from inflarm_model.kinematics import FlexibleArm
        from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, RELIABLE_QOS
        self.arm = arm or FlexibleArm()
        self.poses: dict[tuple[int, int], list[float]] = {}
        self.wrenches: dict[tuple[int, int], object] = {}
        self.forces: list = []  # (stamp [s], force (3,) [N])
        node.create_subscription(JointState, 'estimated_joint_states', self._on_pose,
                                 JOINT_STATE_QOS)
        node.create_subscription(WrenchStamped, 'estimated_wrench', self._on_wrench,
                                 RELIABLE_QOS)

    @staticmethod
    def _key(stamp) -> tuple[int, int]:
        return stamp.sec, stamp.nanosec

    def _on_pose(self, msg) -> None:
        self.poses[self._key(msg.header.stamp)] = list(msg.position)
        self._pair()

    def _on_wrench(self, msg) -> None:
        self.wrenches[self._key(msg.header.stamp)] = msg
        self._pair()

    def _pair(self) -> None:
        import numpy as np
        paired = sorted(self.wrenches.keys() & self.poses.keys())
        for key in paired:
            f = self.wrenches.pop(key).wrench.force
            rotation = self.arm.fk(self.poses.pop(key))[:3, :3]
            self.forces.append((key[0] + key[1] * 1e-9, rotation @ np.array([f.x, f.y, f.z])))
        if paired:
            for unpaired in (self.wrenches, self.poses):
                for key in [k for k in unpaired if k < paired[-1]]:
                    del unpaired[key]

    def __len__(self) -> int:
        return len(self.forces)


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
