"""Long computations off the executor: one daemon thread, the newest waiting job first.

A node whose callbacks would otherwise block its executor (a plan on a fine grid, a long
trajectory's integration) hands the work to a `LatestJobWorker` and takes the results back on
its executor thread: from a timer it runs anyway, or from a guard condition that ``notify``
triggers (rclpy's ``EventsExecutor`` has no guard conditions: a polling node runs on both).
"""

from collections import deque
from collections.abc import Callable
import threading
from typing import Any


class LatestJobWorker:
    """Runs ``run(job)`` for submitted jobs on one daemon thread, in order; a job submitted while
    another is waiting replaces it (the newest request is the one worth answering).

    Parameters
    ----------
    name : str
        The thread's name.
    run : callable
        ``run(job) -> result``, called on the worker thread. An exception it raises is the
        job's result (the executor thread reports it): the worker keeps going.
    notify : callable, optional
        Called on the worker thread after each result (e.g. a guard condition's ``trigger``).
    """

    def __init__(self, name: str, run: Callable[[Any], Any],
                 notify: Callable[[], None] | None = None) -> None:
        self._name = name
        self._run = run
        self._notify = notify
        self._lock = threading.Lock()
        self._next: Any = None
        self._waiting = False
        self._busy = False
        self._closing = False
        self._results: deque = deque()
        self._thread: threading.Thread | None = None
        self._idle = threading.Event()
        self._idle.set()

    @property
    def busy(self) -> bool:
        """A job is running or waiting."""
        with self._lock:
            return self._busy

    def submit(self, job: Any) -> bool:
        """Queue ``job``; True if it replaced a job still waiting. Ignored once closed."""
        with self._lock:
            if self._closing:
                return False
            replaced, self._next, self._waiting = self._waiting, job, True
            start, self._busy = not self._busy, True
            self._idle.clear()
        if start:
            # a daemon: a stop is not held up by a long job, whose result is then dropped
            self._thread = threading.Thread(target=self._work, name=self._name, daemon=True)
            self._thread.start()
        return replaced

    def wait(self, timeout_s: float | None = None) -> bool:
        """Wait until no job is running or waiting (a lock-step replay, where computing takes
        no simulated time); False on timeout."""
        return self._idle.wait(timeout_s)

    def results(self) -> list:
        """The results finished since the last call, oldest first (executor thread)."""
        with self._lock:
            done, self._results = list(self._results), deque()
        return done

    def close(self, timeout_s: float) -> None:
        """Drop the waiting job and future results; wait up to ``timeout_s`` for a running one."""
        with self._lock:
            self._closing = True
            self._next, self._waiting = None, False
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)

    def _work(self) -> None:
        while True:
            with self._lock:
                if not self._waiting or self._closing:
                    self._busy = False
                    self._idle.set()
                    return
                job, self._next, self._waiting = self._next, None, False
            try:
                result = self._run(job)
            except Exception as error:  # noqa: BLE001 (delivered: the executor reports it)
                result = error
            with self._lock:
                if self._closing:
                    self._busy = False
                    self._idle.set()
                    return
                self._results.append(result)
            if self._notify is not None:
                self._notify()
