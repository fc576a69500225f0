"""The one start/stop path of every inflarm node process: ``main()`` is ``spin_node(NodeClass)``.

Start: the stop signals are owned before anything else (`inflarm_msgs_json.ros.signals`);
rclpy is initialized with its own signal handlers off; the nodes are built (a ``ValueError`` or
parameter error there is a bad configuration: logged, exit code 1), and a stop request during
that aborts it at once (what was built is destroyed as below).

Stop (SIGINT, SIGTERM, or a node calling `request_stop`): the request wakes the executor
through its guard condition, the spin loop returns between callbacks, then, in order: the
executor finishes the callbacks in flight, every timer is destroyed (no callback can start
after this point), every node is destroyed (nodes finish their work in ``destroy_node``, e.g. a
bag is closed), and the context is shut down. No rcl call can race the shutdown, so a stop at
any moment exits 0 without a traceback.
"""

from collections.abc import Callable, Sequence
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
import rclpy.logging
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from inflarm_msgs_json.ros.signals import (
    StartupInterrupted,
    add_wakeup,
    install_stop_handlers,
    interruptible_startup,
    remove_wakeup,
    request_stop,
    stop_requested,
)

__all__ = ['request_stop', 'run_nodes', 'spin_node']


def spin_node(make_node: Callable[[], Node], args: list[str] | None = None) -> None:
    """Run one node until a stop request; exit 1 if it cannot be built from its parameters."""
    run_nodes([make_node], args)


def run_nodes(make_nodes: Sequence[Callable[[], Node]], args: list[str] | None = None,
              multithreaded: bool = False) -> None:
    """Run several nodes in this process on one executor until a stop request.

    Parameters
    ----------
    make_nodes : sequence of callables
        Each builds one node (a node class, or ``functools.partial`` of one with overrides).
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (``--ros-args ...``); ``sys.argv`` if None.
    multithreaded : bool
        Spin on a ``MultiThreadedExecutor`` instead of a single thread.
    """
    install_stop_handlers()
    if stop_requested():
        return
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
                    executable = os.path.basename(sys.argv[0]) or 'node'
                    rclpy.logging.get_logger(executable).error(f'cannot start: {error}')
                    sys.exit(1)
        executor = MultiThreadedExecutor() if multithreaded else SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        _spin_until_stop(executor)
    except StartupInterrupted:
        pass  # stopped while the nodes were built
    except ExternalShutdownException:
        pass  # the context was shut down by someone else: stop as for a signal
    finally:
        _stop_in_order(executor, nodes)


def _spin_until_stop(executor: Executor) -> None:
    stopped = Future()

    def wake() -> None:
        stopped.set_result(True)
        executor.wake()

    add_wakeup(wake)
    try:
        executor.spin_until_future_complete(stopped)
    finally:
        remove_wakeup(wake)


def _stop_in_order(executor: Executor | None, nodes: list[Node]) -> None:
    if executor is not None:
        executor.shutdown()  # waits for the callbacks in flight (multi-threaded executor)
    for node in reversed(nodes):
        for timer in list(node.timers):
            node.destroy_timer(timer)
    for node in reversed(nodes):
        node.destroy_node()
    rclpy.try_shutdown()
