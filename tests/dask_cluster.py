"""A real Dask distributed cluster for tests: a ``dask scheduler`` and ``dask worker`` processes.

`DaskCluster` starts the scheduler and each worker as its own process of this Python (``python
-m distributed.cli.dask_scheduler`` / ``dask_worker``, the modules behind the ``dask`` CLI), with
this process's environment (``scripts/env.sh``: the workers import ``inflarm_*``), on loopback
by default. Workers run without a nanny and with one thread, so a worker is one process: SIGKILL
it and it is gone, as a machine that fails. `command` wraps each command line, e.g. in
`netns_hosts.Host.command` to start them inside a network namespace. `stop` kills everything it
started and waits for it; use it in a fixture's teardown. `knowledge_build_command` is a
knowledge build client as its own process, and `filled_points` reads how far a build got.
"""

from collections.abc import Callable
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys

START_TIMEOUT_S = 60.0


def knowledge_build_command(path: Path, grid, address: str, n_trials: int,
                            batch_size: int) -> list[str]:
    """A knowledge build client as its own process: ``build_knowledge_database(path, grid,
    scheduler=address)`` on ``inflarm-build-knowledge``'s plant, without a progress bar."""
    code = (
        'import sys\n'
        'from inflarm_bringup.knowledge_cli import knowledge_plant\n'
        'from inflarm_control.knowledge import KnowledgeGrid, build_knowledge_database\n'
        f'grid = KnowledgeGrid({grid.origin}, {grid.spacing}, {grid.shape})\n'
        'build_knowledge_database(sys.argv[1], grid, plant_factory=knowledge_plant,'
        f' n_trials={n_trials}, batch_size={batch_size}, progress=False, scheduler=sys.argv[2])\n'
        'print("built")\n'
    )
    return [sys.executable, '-c', code, str(path), address]


def filled_points(path: Path) -> int:
    """Knowledge points filled so far in the database at ``path``; 0 before its header is out."""
    from inflarm_control.knowledge import KnowledgeDatabase

    try:
        with KnowledgeDatabase.open(path) as db:
            return db.n_filled
    except (OSError, ValueError):  # not there yet, or its header not written yet
        return 0


def wait_for_workers_command(address: str, n: int) -> list[str]:
    """A process that exits 0 once ``n`` workers have joined the scheduler at ``address``."""
    code = ('import sys\nfrom distributed import Client\n'
            f'with Client(sys.argv[1], timeout={START_TIMEOUT_S}) as client:\n'
            f'    client.wait_for_workers({n}, timeout={START_TIMEOUT_S})\n')
    return [sys.executable, '-c', code, address]


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

    def add_worker(self, host: str = '127.0.0.1', environment: dict[str, str] | None = None,
                   command: Callable[[list[str]], list[str]] | None = None) -> subprocess.Popen:
        """Start one worker (one process, one thread, no nanny) serving at ``host``; ``command``
        wraps its command line instead of the cluster's."""
        process = self._start(f'worker-{len(self.workers)}', [
            '-m', 'distributed.cli.dask_worker', self.address, '--host', host, '--nthreads', '1',
            '--no-nanny', '--no-dashboard', '--local-directory', str(self.directory)],
            environment, command)
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

    def _start(self, name: str, args: list[str], environment: dict[str, str] | None = None,
               command: Callable[[list[str]], list[str]] | None = None) -> subprocess.Popen:
        self.directory.mkdir(parents=True, exist_ok=True)
        with open(self.directory / f'{name}.log', 'wb') as log:
            return subprocess.Popen((command or self.command)([sys.executable, *args]), stdout=log,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    env={**self.environment, **(environment or {})},
                                    cwd=self.directory)
