"""Stop requests from SIGINT and SIGTERM, owned by inflarm from the first moment of a process.

rclpy's own handlers shut the context down asynchronously, from inside whatever call is in
flight, so an rcl call that races them fails (``failed to initialize wait set``, ``Failed to
publish: publisher's context is invalid``; ros2/rclpy#398); and a Ctrl-C that arrives while the
node's modules import is lost or ends in a traceback. Instead, every node executable:

1. installs these handlers first (its entry point, `node_entry`, imports nothing slow before),
   then unblocks SIGINT and SIGTERM -- a parent that must not lose a stop request starts its
   children with both blocked (see ``inflarm_bringup.processes``), so one sent before the
   handlers exist waits for them instead of killing the interpreter;
2. while it imports its node module, a stop request ends the process at once with code 0
   (``os._exit``): nothing is built yet, and no finalizer may run -- an import it interrupts
   can leave an extension's object owned twice (llvmlite's ``ExecutionEngine.add_module``,
   between handing the module to the engine and marking it owned), for two finalizers to free;
3. while it builds its nodes (`interruptible_startup`), a stop request aborts that
   (`StartupInterrupted`) and the process exits 0 once the middleware is shut down;
4. from then on a stop request only sets a flag, from a watcher thread woken through
   ``signal.set_wakeup_fd`` (the main thread may be blocked in rcl's wait); the spin loop looks
   for it between waits (see ``inflarm_msgs_json.ros.spin``), returns between callbacks and
   the node is destroyed in order.

Stdlib only: this module must stay cheap to import.
"""

from collections.abc import Callable, Iterator
import contextlib
import faulthandler
import importlib
import os
import signal
import sys
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
STACKS_SIGNAL = signal.SIGUSR1  # prints every thread's stack to stderr: why a node hangs

_stop = threading.Event()
_exit_at_once = False
_abort_startup = False
_installed = False


class StartupInterrupted(BaseException):
    """Raised into the start-up imports when a stop request arrives (a BaseException, so that
    library code catching ``Exception`` does not swallow it)."""


def _on_signal(signum: int, frame) -> None:
    global _abort_startup
    _stop.set()
    if _exit_at_once:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(0)
    if _abort_startup:
        _abort_startup = False  # once: a second signal must not interrupt the exit
        raise StartupInterrupted(signal.Signals(signum).name)


def _watch_signals(read_fd: int) -> None:
    """Set the stop flag as soon as a stop signal arrives.

    The Python-level handler above runs only when the main thread next executes bytecode, which
    a thread blocked in rcl's wait does not; the interpreter's C-level handler writes the signal
    number to the wake-up fd at once, and this thread reads it.
    """
    stop_numbers = {int(s) for s in STOP_SIGNALS}
    while True:
        try:
            received = os.read(read_fd, 64)
        except OSError:
            return
        if stop_numbers.intersection(received):
            _stop.set()


def install_stop_handlers() -> None:
    """Own SIGINT and SIGTERM from now on (idempotent; main thread only), then unblock them.

    A signal that was blocked and is pending is delivered right here, to the new handler.
    """
    global _installed
    if not _installed:
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        threading.Thread(target=_watch_signals, args=(read_fd,), name='stop-signals',
                         daemon=True).start()
        for signum in STOP_SIGNALS:
            signal.signal(signum, _on_signal)
        faulthandler.register(STACKS_SIGNAL, all_threads=True)
        _installed = True
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def stop_requested() -> bool:
    """Whether SIGINT or SIGTERM has arrived (or `request_stop` was called)."""
    return _stop.is_set()


def request_stop() -> None:
    """Ask the process to stop, as a signal would (for in-process callers)."""
    _stop.set()


def _quiet_unraisable(hook: Callable) -> Callable:
    """``sys.unraisablehook`` that drops a `StartupInterrupted` (see `interruptible_startup`)."""
    def unraisable(info) -> None:
        if not isinstance(info.exc_value, StartupInterrupted):
            hook(info)
    return unraisable


def _quiet_excepthook(hook: Callable) -> Callable:
    """``sys.excepthook`` that drops a `StartupInterrupted` (see `interruptible_startup`)."""
    def excepthook(kind, value, traceback) -> None:
        if not isinstance(value, StartupInterrupted):
            hook(kind, value, traceback)
    return excepthook


def _ignore_unraisable(info) -> None:
    """``sys.unraisablehook`` of a process that only stops: reports nothing (no global names:
    it may run while the interpreter finalizes the modules)."""


@contextlib.contextmanager
def interruptible_startup() -> Iterator[None]:
    """Within this block (main thread), a stop request raises `StartupInterrupted` at once.

    For start-up work that holds nothing accepted yet: building the nodes (a renderer, a
    model), which can take long. A stop request that came before the block is raised on entry.
    Nested blocks are one window.

    Where the exception lands in a C extension's callback, it cannot propagate: the extension
    reports it instead, through ``sys.unraisablehook`` ("Exception ignored in ...", seen in
    scipy's Sobol table loading) and, for Cython's full tracebacks, ``sys.excepthook`` too
    (seen there as well). Both stay quiet about it inside the block; the stop request is
    kept, and start-up stops at its next check. A process whose start-up a stop request
    reached only stops from then on, and the objects the request left half-built (an
    extension's wrapper whose ``__init__`` it interrupted: llvmlite's ``ObjectRef``, seen
    there) fail in their finalizers, at exit at the latest: ``sys.unraisablehook`` stays quiet
    for the rest of the process.
    """
    global _abort_startup
    if _abort_startup:
        yield
        return
    hooks = sys.unraisablehook, sys.excepthook
    sys.unraisablehook, sys.excepthook = _quiet_unraisable(hooks[0]), _quiet_excepthook(hooks[1])
    _abort_startup = True
    try:
        if _stop.is_set():
            _abort_startup = False
            raise StartupInterrupted('stop requested')
        yield
    finally:
        _abort_startup = False
        sys.unraisablehook, sys.excepthook = hooks
        if _stop.is_set():
            sys.unraisablehook = _ignore_unraisable


def node_entry(module: str, function: str = 'main') -> Callable[[], None]:
    """A console-script entry point that owns the stop signals before it imports ``module``.

    ``setup.py`` names these (``'sra_sim = inflarm_hw.executables:sra_sim'``) instead of the
    node module itself, whose imports (rclpy, numpy, Pinocchio) take about a second.
    """
    def entry() -> None:
        global _exit_at_once
        _exit_at_once = True
        try:
            install_stop_handlers()  # a stop request sent before is delivered here
            main = getattr(importlib.import_module(module), function)
        finally:
            _exit_at_once = False
        main()

    entry.__name__ = entry.__qualname__ = module.rsplit('.', 1)[-1]
    entry.__doc__ = f'Run {module}.{function}() with the stop signals owned from the start.'
    return entry
