"""Python launcher for inflarm systems (``launch``/``launch_ros`` are not on PyPI).

``scripts/launch <system> [--duration S] [--log-level LEVEL]`` starts every node of the system as
its own process, as ``ros2 run <pkg> <exe> --ros-args --params-file <share>/config/<exe>.yaml``
would, prefixes their output with the node name, and on Ctrl-C, SIGTERM, the end of
``--duration`` or the death of any node stops them all with SIGINT (SIGKILL after a grace period).
Exit code 0 only when every node exited cleanly.
"""

import argparse
import collections
import dataclasses
from dataclasses import dataclass, field
import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

from ament_index_python.packages import get_package_prefix, get_package_share_directory

SCRIPTS_DIR = pathlib.Path(__file__).resolve().parent
FASTDDS_PROFILE = SCRIPTS_DIR / 'fastdds_profile.xml'


@dataclass(frozen=True)
class NodeProcess:
    """One node executable, its installed YAML config, and overrides."""

    package: str
    executable: str
    parameters: dict[str, object] = field(default_factory=dict)
    # Shared parameter files as (package, file name in its share/config), applied first.
    shared_params: tuple[tuple[str, str], ...] = ()
    remappings: dict[str, str] = field(default_factory=dict)
    log_level: str | None = None

    def command(self) -> list[str]:
        prefix = get_package_prefix(self.package)
        command = [os.path.join(prefix, 'lib', self.package, self.executable), '--ros-args']
        for package, name in self.shared_params:
            command += ['--params-file', _config_path(package, name)]
        config = _config_path(self.package, f'{self.executable}.yaml')
        if os.path.isfile(config):
            command += ['--params-file', config]
        for name, value in self.parameters.items():
            command += ['-p', f'{name}:={_yaml_value(value)}']
        for old, new in self.remappings.items():
            command += ['-r', f'{old}:={new}']
        if self.log_level:
            command += ['--log-level', self.log_level]
        return command


def _config_path(package: str, name: str) -> str:
    return os.path.join(get_package_share_directory(package), 'config', name)


def _yaml_value(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_yaml_value(v) for v in value) + ']'
    return str(value)


# The inflatable arm's geometry, stiffness and pressures, shared by the nodes that model it.
ARM_CONFIG = (('inflarm_model', 'inflatable_arm.yaml'),)

# The systems a user can launch.
INFLATABLE_ARM = (
    NodeProcess('inflarm_model', 'robot_description', shared_params=ARM_CONFIG),
    NodeProcess('inflarm_hw', 'arm_sim', shared_params=ARM_CONFIG),
    NodeProcess('inflarm_estimation', 'load_estimator', shared_params=ARM_CONFIG),
    NodeProcess('inflarm_control', 'elastostatic_ik', shared_params=ARM_CONFIG),
    NodeProcess('inflarm_control', 'tip_path_demo'),
)
SOFT_ARM = (
    NodeProcess('inflarm_hw', 'sra_sim'),
    NodeProcess('inflarm_control', 'pressure_controller', parameters={'trial_duration_s': 10.0}),
    NodeProcess('inflarm_control', 'trial_runner'),
)
SYSTEMS: dict[str, tuple[NodeProcess, ...]] = {
    'sim': INFLATABLE_ARM + SOFT_ARM,  # the default: both simulated arms
    'arm': INFLATABLE_ARM,
    'sra': SOFT_ARM,
    'smoke': (
        NodeProcess('inflarm_hw', 'demo_joint_publisher'),
        NodeProcess('inflarm_hw', 'joint_state_monitor'),
    ),
}


def ros_environment(base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment nodes run in: local discovery, fast announcements, UDP transport.

    Values already set by the user win; the defaults keep DDS traffic on this machine.
    """
    env = dict(os.environ if base is None else base)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(FASTDDS_PROFILE))
    # Shared memory stalls on messages over ~512 KB (camera images); UDP does not.
    env.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env['PYTHONUNBUFFERED'] = '1'
    return env


# Node processes start with these blocked: a stop request sent before a node has installed its
# handlers waits for them instead of killing the interpreter (inflarm_msgs_json.ros.signals).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
LAST_LINES = 15  # output lines kept per process, shown when it dies or hangs


def start_node_process(command: list[str], env: dict[str, str], **popen_args) -> subprocess.Popen:
    """Popen ``command`` in a session of its own with the stop signals blocked until the node
    unblocks them; a terminal's Ctrl-C reaches only the parent, which forwards it."""
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        return subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL,
                                start_new_session=True, **popen_args)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


class ProcessGroup:
    """Child processes started together and stopped together."""

    def __init__(self, env: dict[str, str] | None = None, output=sys.stdout) -> None:
        self.env = ros_environment(env)
        self.output = output
        self.processes: dict[str, subprocess.Popen] = {}
        self.last_lines: dict[str, collections.deque[str]] = {}
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def start(self, name: str, command: list[str]) -> subprocess.Popen:
        process = start_node_process(command, self.env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1)
        self.processes[name] = process
        self.last_lines[name] = collections.deque(maxlen=LAST_LINES)
        thread = threading.Thread(target=self._relay, args=(name, process), daemon=True)
        thread.start()
        self._threads.append(thread)
        return process

    def _relay(self, name: str, process: subprocess.Popen) -> None:
        for line in process.stdout:
            with self._lock:
                self.last_lines[name].append(line.rstrip('\n'))
                self.output.write(f'[{name}] {line}')
                self.output.flush()

    def first_exited(self) -> str | None:
        return next((n for n, p in self.processes.items() if p.poll() is not None), None)

    def describe(self, name: str, what: str) -> str:
        """``what`` happened to ``name``, with its last output lines."""
        with self._lock:
            lines = '\n'.join(f'    {line}' for line in self.last_lines[name]) or '    (none)'
        return f'[launch] {name} {what}; its last output:\n{lines}'

    def stop(self, grace_s: float = 10.0) -> dict[str, int]:
        """SIGINT every running child, SIGKILL those still alive after ``grace_s``.

        Returns each child's exit code (negative: killed by that signal).
        """
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + grace_s
        hung = []
        for name, process in self.processes.items():
            try:
                process.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                hung.append(name)
                process.send_signal(signal.SIGUSR1)  # the node prints its threads' stacks
                try:
                    process.wait(timeout=1.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
        for thread in self._threads:
            thread.join(timeout=2.0)
        for name in hung:
            print(self.describe(name, f'did not stop within {grace_s:g} s of SIGINT: killed'),
                  file=sys.stderr)
        return {name: process.returncode for name, process in self.processes.items()}


def launch(nodes: tuple[NodeProcess, ...], duration_s: float | None) -> int:
    group = ProcessGroup()
    stop_requested = threading.Event()

    def request_stop(signum, frame) -> None:
        stop_requested.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    for node in nodes:
        group.start(node.executable, node.command())
    deadline = None if duration_s is None else time.monotonic() + duration_s
    died = None
    while not stop_requested.is_set():
        died = group.first_exited()
        if died is not None or (deadline is not None and time.monotonic() >= deadline):
            break
        stop_requested.wait(0.1)
    if died is not None:
        print(group.describe(died, f'exited with code {group.processes[died].returncode}; '
                                   'stopping the system'), file=sys.stderr)
    codes = group.stop()
    failed = {name: code for name, code in codes.items() if code != 0}
    if failed:
        print(f'[launch] nodes that did not exit cleanly: {failed}', file=sys.stderr)
    return 1 if failed or died is not None else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('system', nargs='?', default=next(iter(SYSTEMS)), choices=SYSTEMS)
    parser.add_argument('--duration', type=float, default=None,
                        help='stop the system after this many seconds (default: run until Ctrl-C)')
    parser.add_argument('--log-level', default=None, help='log level for every node')
    args = parser.parse_args()
    nodes = tuple(
        dataclasses.replace(node, log_level=args.log_level) for node in SYSTEMS[args.system])
    sys.exit(launch(nodes, args.duration))


if __name__ == '__main__':
    main()
