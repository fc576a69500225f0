"""A real Dask distributed cluster for tests: a ``dask scheduler`` and ``dask worker`` processes.

`DaskCluster` starts the scheduler and each worker as its own process of this Python (``python
-m distributed.cli.dask_scheduler`` / ``dask_worker``, the modules behind the ``dask`` CLI), with
this process's environment (``scripts/env.sh``: the workers import ``inflarm_*``), on loopback
by default. Workers run without a nanny and with one thread, so a worker is one process: SIGKILL
it and it is gone, as a machine that fails. `command` wraps each command line, e.g. in
`netns_hosts.Host.command` to start them inside a network namespace. `stop` kills everything it
started and waits for it; use it in a fixture's teardown.
"""

from collections.abc import Callable
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys

START_TIMEOUT_S = 60.0


def free_port(host: str = '127.0.0.1') -> int:
    """A TCP port nothing listens on at ``host`` right now."""
    with socket.socket() as sock:
        sock.bind((host, 0))
        return sock.getsockname()[1]


class DaskCluster:
    """A scheduler at ``tcp://host:port`` and the workers started with `add_worker`.

    Parameters
    ----------
    directory : pathlib.Path
        Where the processes keep their scratch space and their logs (``scheduler.log``,
        ``worker-N.log``).
    host : str
        Address the scheduler listens on.
    port : int, optional
        Its port; a free one of loopback by default.
    command : callable, optional
        Wraps each command line (list of str) before it is started.
    environment : dict, optional
        Extra environment variables of every process.
    """

    def __init__(self, directory: Path, host: str = '127.0.0.1', port: int | None = None,
                 command: Callable[[list[str]], list[str]] = lambda argv: argv,
                 environment: dict[str, str] | None = None) -> None:
        self.directory = Path(directory)
        self.command = command
        self.environment = {**os.environ, **(environment or {})}
        self.port = free_port(host) if port is None else port
        self.address = f'tcp://{host}:{self.port}'
        self.workers: list[subprocess.Popen] = []
        self.scheduler = self._start('scheduler', [
            '-m', 'distributed.cli.dask_scheduler', '--host', host, '--port', str(self.port),
            '--no-dashboard', '--no-show'])

    def add_worker(self, host: str = '127.0.0.1',
                   environment: dict[str, str] | None = None) -> subprocess.Popen:
        """Start one worker (one process, one thread, no nanny) serving at ``host``."""
        process = self._start(f'worker-{len(self.workers)}', [
            '-m', 'distributed.cli.dask_worker', self.address, '--host', host, '--nthreads', '1',
            '--no-nanny', '--no-dashboard', '--local-directory', str(self.directory)],
            environment)
        self.workers.append(process)
        return process

    def wait_for_workers(self, n: int) -> None:
        """Return once ``n`` workers have joined the scheduler (from this process)."""
        from distributed import Client

        with Client(self.address, timeout=START_TIMEOUT_S, set_as_default=False) as client:
            client.wait_for_workers(n, timeout=START_TIMEOUT_S)

    def log(self, name: str) -> str:
        """What process ``name`` (``'scheduler'``, ``'worker-0'``, ...) printed so far."""
        return (self.directory / f'{name}.log').read_text(errors='replace')

    def stop(self) -> None:
        """SIGKILL every process started and wait for it."""
        for process in [*self.workers, self.scheduler]:
            if process.poll() is None:
                process.send_signal(signal.SIGKILL)
            process.wait(timeout=10)

    def _start(self, name: str, args: list[str],
               environment: dict[str, str] | None = None) -> subprocess.Popen:
        self.directory.mkdir(parents=True, exist_ok=True)
        with open(self.directory / f'{name}.log', 'wb') as log:
            return subprocess.Popen(self.command([sys.executable, *args]), stdout=log,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    env={**self.environment, **(environment or {})},
                                    cwd=self.directory)
