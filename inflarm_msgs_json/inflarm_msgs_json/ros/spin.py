"""The one start/stop path of every inflarm node process: ``main()`` is ``spin_node(NodeClass)``.

Start: the stop signals are owned before anything else (`inflarm_msgs_json.ros.signals`);
rclpy is initialized with its own signal handlers off; the nodes are built (a ``ValueError`` or
parameter error there is a bad configuration: logged, exit code 1), and a stop request during
that aborts it at once (what was built is destroyed as below).

Stop (SIGINT, SIGTERM, or a node calling `request_stop`): the spin loop sees the request
within ``STOP_POLL_PERIOD_S`` and returns between callbacks, then, in order: the
executor finishes the callbacks in flight, every timer is destroyed (no callback can start
after this point), every node is destroyed (nodes finish their work in ``destroy_node``, e.g. a
bag is closed), and the context is shut down. No rcl call can race the shutdown, so a stop at
any moment exits 0 without a traceback.

Executor: ``single_threaded`` (rclpy's Python ``SingleThreadedExecutor``) or ``events``
(``rclpy.experimental.EventsExecutor``, rclpy's C++ executor: less CPU per message, but no
guard conditions, which ``path_planner``'s planning thread needs). A node's executable names its
default (`spin_node`'s ``default_executor``: ``load_estimator``, the node fed at 1 kHz, takes
``events``; every other, `DEFAULT_EXECUTOR`); ``INFLARM_EXECUTOR`` in the environment
overrides it for any node process, one way for all. An unknown name is a bad configuration
(exit 1). ``run_nodes(..., multithreaded=True)`` (several nodes in one process
whose callbacks may block each other) takes rclpy's ``MultiThreadedExecutor`` whatever the
environment says. The estimation README gives the measurements behind the default.

Scheduling: a node's executable may name a real-time priority (`spin_node`'s
``default_realtime_priority``: ``load_estimator`` takes 50, ros2_control's default for its
control thread; every other node 0, the normal time-shared scheduling);
``INFLARM_REALTIME_PRIORITY`` (0-99) overrides it for any node process. Once the nodes are
built, every thread of the process (the executor's and the middleware's, which receives in
threads of its own) is put under ``SCHED_FIFO`` at that priority, so that other jobs on a busy
machine cannot keep the node from its samples. Without the permission (an ``rtprio`` limit, or
root) the node logs a warning and runs at normal priority.
"""

from collections.abc import Callable, Sequence
import contextlib
import os
import sys

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.experimental import EventsExecutor
import rclpy.logging
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from inflarm_msgs_json.ros.signals import (
    StartupInterrupted,
    install_stop_handlers,
    interruptible_startup,
    request_stop,
    stop_requested,
)

__all__ = ['DEFAULT_EXECUTOR', 'EXECUTORS', 'EXECUTOR_ENV', 'REALTIME_PRIORITY_ENV',
           'executor_kind', 'make_executor', 'realtime_priority', 'request_stop', 'run_nodes',
           'scheduling', 'spin_node', 'take_realtime_priority']

EXECUTOR_ENV = 'INFLARM_EXECUTOR'
EXECUTORS = {'events': EventsExecutor, 'single_threaded': SingleThreadedExecutor}
"""The executors a node process can spin on, by the name ``INFLARM_EXECUTOR`` gives."""
DEFAULT_EXECUTOR = 'single_threaded'


def executor_kind(environ: dict[str, str] | None = None, default: str = DEFAULT_EXECUTOR) -> str:
    """The executor named by ``INFLARM_EXECUTOR`` (``default`` when unset or empty).

    Raises
    ------
    ValueError
        If the name is not a key of `EXECUTORS`.
    """
    kind = (os.environ if environ is None else environ).get(EXECUTOR_ENV, '').strip()
    kind = kind or default
    if kind not in EXECUTORS:
        raise ValueError(f'expected {EXECUTOR_ENV} in {sorted(EXECUTORS)}, got {kind!r}')
    return kind


REALTIME_PRIORITY_ENV = 'INFLARM_REALTIME_PRIORITY'


def realtime_priority(environ: dict[str, str] | None = None, default: int = 0) -> int:
    """The ``SCHED_FIFO`` priority named by ``INFLARM_REALTIME_PRIORITY`` (``default`` when
    unset or empty): 1-99, or 0 for the normal time-shared scheduling.

    Raises
    ------
    ValueError
        If it is not an integer from 0 to 99.
    """
    value = (os.environ if environ is None else environ).get(REALTIME_PRIORITY_ENV, '').strip()
    if not value:
        return default
    try:
        priority = int(value)
    except ValueError:
        priority = -1
    if not 0 <= priority <= 99:
        raise ValueError(f'expected {REALTIME_PRIORITY_ENV} an integer from 0 to 99 '
                         f'(0: no real-time priority), got {value!r}')
    return priority


def take_realtime_priority(priority: int) -> str | None:
    """Put every thread of this process under ``SCHED_FIFO`` at ``priority`` (1-99; 0: back
    to the normal ``SCHED_OTHER``); threads and processes started later inherit it. None when
    done, else why not (no permission, no such policy)."""
    policy = os.SCHED_FIFO if priority > 0 else os.SCHED_OTHER
    done: set[str] = set()
    try:
        # again until no thread is new: one started meanwhile by a thread not yet set
        while tids := set(os.listdir('/proc/self/task')) - done:
            for tid in tids:
                with contextlib.suppress(ProcessLookupError):  # the thread ended meanwhile
                    os.sched_setscheduler(int(tid), policy, os.sched_param(priority))
            done |= tids
    except AttributeError:
        return 'this platform has no SCHED_FIFO'
    except OSError as error:
        return error.strerror or str(error)
    return None


def scheduling() -> str:
    """This thread's policy and priority: ``'SCHED_FIFO 50'``, ``'SCHED_OTHER'`` (``'unknown'``
    where the platform does not say)."""
    if not hasattr(os, 'sched_getscheduler'):
        return 'unknown'
    policy = os.sched_getscheduler(0)
    if policy == os.SCHED_FIFO:
        return f'SCHED_FIFO {os.sched_getparam(0).sched_priority}'
    return {os.SCHED_RR: 'SCHED_RR', os.SCHED_BATCH: 'SCHED_BATCH',
            os.SCHED_IDLE: 'SCHED_IDLE'}.get(policy, 'SCHED_OTHER')


def make_executor(kind: str | None = None, *, multithreaded: bool = False) -> Executor:
    """The executor of ``kind`` (a key of `EXECUTORS`; `executor_kind` if None), on the
    default context; a ``MultiThreadedExecutor`` if ``multithreaded``."""
    if multithreaded:
        return MultiThreadedExecutor()
    return EXECUTORS[executor_kind() if kind is None else kind]()


def spin_node(make_node: Callable[[], Node], args: list[str] | None = None,
              default_executor: str = DEFAULT_EXECUTOR,
              default_realtime_priority: int = 0) -> None:
    """Run one node until a stop request on ``default_executor`` (a key of `EXECUTORS`) unless
    ``INFLARM_EXECUTOR`` names another, at ``default_realtime_priority`` unless
    ``INFLARM_REALTIME_PRIORITY`` names another; exit 1 if it cannot be built from its
    parameters."""
    run_nodes([make_node], args, default_executor=default_executor,
              default_realtime_priority=default_realtime_priority)


def run_nodes(make_nodes: Sequence[Callable[[], Node]], args: list[str] | None = None,
              multithreaded: bool = False, default_executor: str = DEFAULT_EXECUTOR,
              default_realtime_priority: int = 0) -> None:
    """Run several nodes in this process on one executor until a stop request.

    Parameters
    ----------
    make_nodes : sequence of callables
        Each builds one node (a node class, or ``functools.partial`` of one with overrides).
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (``--ros-args ...``); ``sys.argv`` if None.
    multithreaded : bool
        Spin on a ``MultiThreadedExecutor`` instead.
    default_executor : str
        The executor (a key of `EXECUTORS`) unless ``INFLARM_EXECUTOR`` names another.
    default_realtime_priority : int
        The ``SCHED_FIFO`` priority of the process's threads (0: none) unless
        ``INFLARM_REALTIME_PRIORITY`` names another.
    """
    install_stop_handlers()
    if stop_requested():
        return
    logger = rclpy.logging.get_logger(os.path.basename(sys.argv[0]) or 'node')
    try:
        kind = executor_kind(default=default_executor)
        priority = realtime_priority(default=default_realtime_priority)
    except ValueError as error:
        logger.error(f'cannot start: {error}')
        sys.exit(1)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[Node] = []
    executor: Executor | None = None
    try:
        with interruptible_startup():
            for make_node in make_nodes:
                try:
                    nodes.append(make_node())
                except (ValueError, ParameterException) as error:
                    # A bad configuration: the message says more than a traceback would.
                    logger.error(f'cannot start: {error}')
                    sys.exit(1)
        executor = make_executor(kind, multithreaded=multithreaded)
        if priority > 0:  # now that the middleware's threads exist
            problem = take_realtime_priority(priority)
            if problem is None:
                logger.info(f'scheduling: SCHED_FIFO, priority {priority}')
            else:
                logger.warning(
                    f'cannot take real-time priority {priority} (SCHED_FIFO): {problem}; '
                    'running at normal priority, where other jobs can delay this node (grant '
                    f'an rtprio limit, or set {REALTIME_PRIORITY_ENV}=0 to silence this)')
        for node in nodes:
            executor.add_node(node)
        _spin_until_stop(executor)
    except StartupInterrupted:
        pass  # stopped while the nodes were built
    except ExternalShutdownException:
        pass  # the context was shut down by someone else: stop as for a signal
    finally:
        _stop_in_order(executor, nodes)


# How often the spin loop looks for a stop request [s]: the longest a stop waits to begin.
STOP_POLL_PERIOD_S = 0.05


def _spin_until_stop(executor: Executor) -> None:
    """Spin until a stop request, looking for one every ``STOP_POLL_PERIOD_S``.

    Polled, not pushed: the ``EventsExecutor`` of this rclpy (7.1) supports no guard
    conditions, deadlocks when a future is completed from another thread, and never returns
    from ``spin_until_future_complete`` without a timeout; with one it serves every callback
    and returns on time.
    """
    never = Future()
    while not stop_requested():
        executor.spin_until_future_complete(never, timeout_sec=STOP_POLL_PERIOD_S)


def _stop_in_order(executor: Executor | None, nodes: list[Node]) -> None:
    if executor is not None:
        executor.shutdown()  # waits for the callbacks in flight (multi-threaded executor)
    for node in reversed(nodes):
        for timer in list(node.timers):
            node.destroy_timer(timer)
    for node in reversed(nodes):
        node.destroy_node()
    rclpy.try_shutdown()
