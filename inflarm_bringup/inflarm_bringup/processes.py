"""Node executables as processes: their command lines, their environment, and a group of them
started and stopped together. What ``ros2 run`` and ``ros2 launch`` do, for this workspace.

- `NodeProcess` builds ``<prefix>/lib/<pkg>/<exe> --ros-args --params-file ...``: the shared
  files first, then the node's installed ``config/<exe>.yaml``, then the system's file, then the
  overrides (written as a file keyed by the node's name: a ``-p`` given after a ``/**`` file loses
  to the node's own YAML, an rcl subtlety).
- `ros_environment` keeps DDS on this machine, with fast discovery and shared memory large
  enough for camera images (``config/fastdds_profile.xml``).
- `start_node_process` starts one with SIGINT and SIGTERM blocked until the node owns them
  (``inflarm_msgs_json.ros.signals``): a stop request at any moment is never lost.
- `ProcessGroup` relays their output prefixed by name, keeps each one's last lines, and stops
  them one at a time, the last started first (SIGINT, then SIGKILL after a grace period,
  reporting what hung with its threads' stacks).
"""

import atexit
import collections
from dataclasses import dataclass, field
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import tempfile
import threading

from ament_index_python.packages import (
    PackageNotFoundError,
    get_package_prefix,
    get_package_share_directory,
)
import yaml

# Node processes start with these blocked: a stop request sent before a node has installed its
# handlers waits for them instead of killing the interpreter (inflarm_msgs_json.ros.signals).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
LAST_LINES = 15  # output lines kept per process, shown when it dies or hangs


@dataclass(frozen=True)
class NodeProcess:
    """One node executable with its configuration.

    Attributes
    ----------
    package, executable : str
        What ``ros2 run`` takes; the node's name is the executable's unless ``name`` is given.
    parameters : dict
        Overrides, applied after every file.
    shared_params : tuple of (package, file)
        Parameter files in a package's ``share/config``, applied first (e.g. the inflatable
        arm's ``inflatable_arm.yaml``, keyed ``/**``).
    system_params : tuple of (package, file)
        The system's parameter files, applied after the node's own config.
    remappings : dict
        Topic remappings ``{old: new}``.
    arguments : tuple of str
        The executable's own arguments, before ``--ros-args`` (e.g. ``rviz2 -d FILE``).
    name : str, optional
        Node name (``__node`` remap); also the key of its parameter sections.
    log_level : str, optional
    """

    package: str
    executable: str
    parameters: dict[str, object] = field(default_factory=dict)
    shared_params: tuple[tuple[str, str], ...] = ()
    system_params: tuple[tuple[str, str], ...] = ()
    remappings: dict[str, str] = field(default_factory=dict)
    arguments: tuple[str, ...] = ()
    name: str | None = None
    log_level: str | None = None

    @property
    def node_name(self) -> str:
        return self.name or self.executable

    def parameter_files(self) -> list[str]:
        """The parameter files, in the order they apply: the node's own one if it exists (a
        package of another suite, or one not installed here, has none)."""
        files = [config_path(package, name) for package, name in self.shared_params]
        try:
            own = config_path(self.package, f'{self.executable}.yaml')
        except PackageNotFoundError:
            own = ''
        if os.path.isfile(own):
            files.append(own)
        return files + [config_path(package, name) for package, name in self.system_params]

    def ros_arguments(self) -> list[str]:
        """``--ros-args`` and what follows: files, overrides, remappings, name, log level."""
        arguments = ['--ros-args']
        for path in self.parameter_files():
            arguments += ['--params-file', path]
        if self.parameters:
            arguments += ['--params-file', overrides_file(self.node_name, self.parameters)]
        if self.name:
            arguments += ['-r', f'__node:={self.name}']
        for old, new in self.remappings.items():
            arguments += ['-r', f'{old}:={new}']
        if self.log_level:
            arguments += ['--log-level', self.log_level]
        return arguments

    def command(self) -> list[str]:
        """The command line, as ``ros2 run`` would exec it."""
        prefix = get_package_prefix(self.package)
        return [os.path.join(prefix, 'lib', self.package, self.executable),
                *self.arguments, *self.ros_arguments()]


def is_installed(package: str) -> bool:
    """Whether the ament index knows ``package``."""
    try:
        get_package_prefix(package)
    except PackageNotFoundError:
        return False
    return True


def config_path(package: str, name: str) -> str:
    """``share/<package>/config/<name>`` of an installed package."""
    return os.path.join(get_package_share_directory(package), 'config', name)


_overrides_dir: pathlib.Path | None = None


def overrides_file(node_name: str, parameters: dict[str, object]) -> str:
    """A parameter file setting ``parameters`` of the node ``node_name`` in any namespace (kept
    until this process exits). Its key is new to the node's parameter files, so rcl applies it
    after them."""
    global _overrides_dir
    if _overrides_dir is None:
        _overrides_dir = pathlib.Path(tempfile.mkdtemp(prefix='inflarm-parameters-'))
        atexit.register(shutil.rmtree, _overrides_dir, ignore_errors=True)
    values = {k: list(v) if isinstance(v, tuple) else v for k, v in parameters.items()}
    handle, path = tempfile.mkstemp(prefix=f'{node_name}-', suffix='.yaml', dir=_overrides_dir)
    with os.fdopen(handle, 'w') as file:
        yaml.safe_dump({f'/**/{node_name}': {'ros__parameters': values}}, file)
    return path


def ros_environment(base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment nodes run in: local discovery, fast announcements, shared memory with a
    16 MB segment (and UDPv4), from ``config/fastdds_profile.xml``.

    Values already set by the user win; the defaults keep DDS traffic on this machine.
    """
    env = dict(os.environ if base is None else base)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', config_path('inflarm_bringup',
                                                                 'fastdds_profile.xml'))
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env['PYTHONUNBUFFERED'] = '1'
    return env


def start_node_process(command: list[str], env: dict[str, str], **popen_args) -> subprocess.Popen:
    """Popen ``command`` in a session of its own with the stop signals blocked until the node
    unblocks them; a terminal's Ctrl-C reaches only the parent, which forwards it."""
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        return subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL,
                                start_new_session=True, **popen_args)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def native_stacks(pid: int, timeout_s: float = 30.0) -> str | None:
    """Every thread's native stack in process ``pid``, as gdb prints them; None without gdb or
    when it cannot attach.

    A node stuck in the middleware shows only the Python call into it in its own stack dump;
    the native frames name the lock it waits on (Fast DDS, rmw).
    """
    gdb = shutil.which('gdb')
    if gdb is None:
        return None
    try:
        run = subprocess.run([gdb, '-p', str(pid), '-batch', '-nx', '-ex', 'thread apply all bt'],
                             stdin=subprocess.DEVNULL, capture_output=True, text=True,
                             timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return None
    return run.stdout if '#0 ' in run.stdout else None


class ProcessGroup:
    """Child processes started together and stopped together."""

    def __init__(self, env: dict[str, str] | None = None, output=sys.stdout) -> None:
        self.env = ros_environment(env)
        self.output = output
        self.processes: dict[str, subprocess.Popen] = {}
        self.commands: dict[str, list[str]] = {}
        self.last_lines: dict[str, collections.deque[str]] = {}
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def start(self, name: str, command: list[str]) -> subprocess.Popen:
        """Start (or restart) ``command`` as ``name``."""
        process = start_node_process(command, self.env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1)
        self.processes[name] = process
        self.commands[name] = command
        self.last_lines.setdefault(name, collections.deque(maxlen=LAST_LINES))
        thread = threading.Thread(target=self._relay, args=(name, process), daemon=True)
        thread.start()
        self._threads.append(thread)
        return process

    def _relay(self, name: str, process: subprocess.Popen) -> None:
        for line in process.stdout:
            self._write(name, [line.rstrip('\n')])

    def _write(self, name: str, lines: list[str], keep: bool = True) -> None:
        """``lines`` to the output, each prefixed with ``name``; ``keep``: among its last lines."""
        with self._lock:
            for line in lines:
                if keep:
                    self.last_lines[name].append(line)
                self.output.write(f'[{name}] {line}\n')
            self.output.flush()

    def exited(self) -> list[str]:
        """The names of the processes that have exited."""
        return [n for n, p in self.processes.items() if p.poll() is not None]

    def first_exited(self) -> str | None:
        return next(iter(self.exited()), None)

    def describe(self, name: str, what: str) -> str:
        """``what`` happened to ``name``, with its last output lines."""
        with self._lock:
            lines = '\n'.join(f'    {line}' for line in self.last_lines[name]) or '    (none)'
        return f'[launch] {name} {what}; its last output:\n{lines}'

    def stop(self, grace_s: float = 10.0) -> dict[str, int]:
        """Stop every running child, the last started first: SIGINT, then SIGKILL if it is
        still alive ``grace_s`` later.

        One at a time because of a Fast DDS 2.14 bug (eProsima/Fast-DDS#6513): deleting a
        participant while one of its discovery callbacks runs can spin for ever. Seen here with
        gdb, 1 stop in about 1,000 with all nodes stopped at once: the main thread spinning in
        ``DomainParticipant::set_listener`` (from ``rmw_destroy_node``), the callback's thread
        blocked on a mutex in ``onReaderDiscovery``. Stopped at once, each node hears of the
        others' endpoints going away while it deletes its own participant; stopped alone, it
        hears of no one leaving.

        Returns each child's exit code (negative: killed by that signal). A child that hung
        first has its threads' native stacks written to the output (`native_stacks`), then gets
        SIGUSR1, on which an inflarm node prints every thread's Python stack.
        """
        hung = []
        for name, process in reversed(list(self.processes.items())):
            if process.poll() is not None:
                continue
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                hung.append(name)
                stacks = native_stacks(process.pid)
                if stacks is not None:
                    self._write(name, ['native stacks (gdb):', *stacks.splitlines()], keep=False)
                process.send_signal(signal.SIGUSR1)
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
