"""``inflarm-launch``: start an inflarm system, the ``ros2 launch`` of this workspace.

    inflarm-launch [SYSTEM] [--backend sim|sim_mcu|hardware] [--port DEVICE]
                   [--on-exit stop|restart|ignore] [--in-process] [--duration S]
                   [--log-level LEVEL] [--rviz] [--camera-transport raw|compressed]
                   [--view] [--view-host HOST] [--view-port PORT]

Each node of the system (``inflarm_bringup.systems``) runs as its own process with its
parameter files, its output prefixed by its name. Ctrl-C or SIGTERM (or the end of
``--duration``) stops them all with SIGINT, and SIGKILL after a grace period. A node that
exits on its own is reported, with its exit code and last lines, and then by ``--on-exit``:
the system stops (``stop``, the default), the node is started again (``restart``, at most
``--max-restarts`` times), or the others go on (``ignore``). Exit code 0 only when every node
exited cleanly and none died.

``--in-process`` runs every node in this one process instead, on a multi-threaded executor
(the nodes' parameter files apply as in separate processes).

``--camera-transport`` sends the camera images raw or JPEG-compressed: it sets the simulated
camera's ``camera.transport`` and ``ball_tracker``'s ``transport`` (default: as their parameter
files say, raw).

``--view`` adds the live view (``live_view``: both arms in a browser, with controls on the
simulated backends) and prints its URL; ``--view-host 0.0.0.0`` serves it to the network.

``--rviz`` adds ``robot_state_publisher``, the static frames and RViz
(`inflarm_bringup.systems.visualization_nodes`), from a ROS 2 Jazzy install.
"""

import argparse
import collections
import functools
import importlib
import inspect
import os
import signal
import sys
import threading
import time

from inflarm_bringup.processes import NodeProcess, ProcessGroup, is_installed, ros_environment
from inflarm_bringup.systems import (
    BACKENDS,
    CAMERA_TRANSPORTS,
    SYSTEMS,
    VIEW_HOST,
    VIEW_PORT,
    VISUALIZATION_PACKAGES,
    backend,
    live_view_node,
    live_view_url,
    system_nodes,
    visualization_nodes,
)

ON_EXIT = ('stop', 'restart', 'ignore')


def launch(nodes: tuple[NodeProcess, ...], duration_s: float | None = None,
           on_exit: str = 'stop', max_restarts: int = 3, output=sys.stdout) -> int:
    """Run ``nodes`` as processes until a stop request, ``duration_s`` or (``on_exit='stop'``)
    the death of one; return 0 if every node exited cleanly and none died."""
    if on_exit not in ON_EXIT:
        raise ValueError(f'on_exit must be one of {list(ON_EXIT)}, got {on_exit!r}')
    group = ProcessGroup(output=output)
    stop_requested = threading.Event()

    def request_stop(signum, frame) -> None:
        stop_requested.set()

    previous = {s: signal.signal(s, request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        for node in nodes:
            group.start(node.node_name, node.command())
        deadline = None if duration_s is None else time.monotonic() + duration_s
        restarts: collections.Counter[str] = collections.Counter()
        left: set[str] = set()  # exited, reported, not restarted
        died = False
        while not stop_requested.is_set():
            if deadline is not None and time.monotonic() >= deadline:
                break
            for name in set(group.exited()) - left:
                died = True
                code = group.processes[name].returncode
                if on_exit == 'restart' and restarts[name] < max_restarts:
                    restarts[name] += 1
                    what = f'restart {restarts[name]} of {max_restarts}'
                    group.start(name, group.commands[name])
                else:
                    left.add(name)
                    what = 'stopping the system' if on_exit == 'stop' else 'left stopped'
                    if on_exit == 'stop':
                        stop_requested.set()
                print(group.describe(name, f'exited with code {code}; {what}'),
                      file=sys.stderr)
            stop_requested.wait(0.1)
        codes = group.stop()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    failed = {name: code for name, code in codes.items() if code != 0}
    if failed:
        print(f'[launch] nodes that did not exit cleanly: {failed}', file=sys.stderr)
    return 1 if failed or died else 0


def node_class(node: NodeProcess) -> type:
    """The node class an executable runs (the Node subclass its module defines)."""
    module = importlib.import_module(f'{node.package}.nodes.{node.executable}')
    from rclpy.node import Node
    classes = [c for _, c in inspect.getmembers(module, inspect.isclass)
               if issubclass(c, Node) and c.__module__ == module.__name__]
    if len(classes) != 1:
        raise ValueError(f'{module.__name__} defines {len(classes)} node classes, expected 1')
    return classes[0]


def in_process_arguments(nodes: tuple[NodeProcess, ...]) -> list[str]:
    """The ROS arguments of one context holding all of ``nodes``: every node's parameter
    files, a shared one once (each file keys its values by node name or ``/**``)."""
    arguments = ['--ros-args']
    for node in nodes:
        for path in node.parameter_files():
            if path not in arguments:
                arguments += ['--params-file', path]
    return arguments


def launch_in_process(nodes: tuple[NodeProcess, ...], duration_s: float | None = None) -> None:
    """Run ``nodes`` in this process on one multi-threaded executor until a stop request."""
    from rclpy.parameter import Parameter

    from inflarm_msgs_json.ros.signals import request_stop
    from inflarm_msgs_json.ros.spin import run_nodes

    arguments = in_process_arguments(nodes)
    factories = [functools.partial(node_class(n), parameter_overrides=[
        Parameter(k, value=list(v) if isinstance(v, tuple) else v)
        for k, v in n.parameters.items()]) for n in nodes]
    if duration_s is not None:
        threading.Timer(duration_s, request_stop).start()
    run_nodes(factories, [sys.argv[0], *arguments], multithreaded=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='inflarm-launch',
                                     description=__doc__.splitlines()[0].split(': ', 1)[1])
    parser.add_argument('system', nargs='?', default=next(iter(SYSTEMS)), choices=SYSTEMS)
    parser.add_argument('--backend', default='sim', choices=BACKENDS,
                        help='the robots: simulators (default), the bridge on a simulated '
                             'MCU, or the bridge on real hardware')
    parser.add_argument('--port', default='',
                        help='hardware: the MCU serial device; sim_mcu: the pty link to make '
                             '(default: a fresh temporary path)')
    parser.add_argument('--on-exit', default='stop', choices=ON_EXIT,
                        help='when a node exits on its own: stop the system (default), '
                             'restart the node, or ignore it')
    parser.add_argument('--max-restarts', type=int, default=3)
    parser.add_argument('--in-process', action='store_true',
                        help='every node in this process, on a multi-threaded executor')
    parser.add_argument('--duration', type=float, default=None,
                        help='stop the system after this many seconds (default: until Ctrl-C)')
    parser.add_argument('--log-level', default=None, help='log level for every node')
    parser.add_argument('--rviz', action='store_true',
                        help='also robot_state_publisher, the static frames and RViz '
                             '(from a ROS 2 Jazzy install)')
    parser.add_argument('--camera-transport', default=None, choices=CAMERA_TRANSPORTS,
                        help="camera images as sensor_msgs/Image ('raw') or JPEG "
                             "CompressedImage ('compressed'), from the simulated camera to "
                             'ball_tracker (default: as configured, raw)')
    parser.add_argument('--view', action='store_true',
                        help='also the live view: both arms in a browser, with controls on the '
                             'simulated backends')
    parser.add_argument('--view-host', default=VIEW_HOST,
                        help="address the view serves on (default %(default)s; '0.0.0.0': the "
                             'network: its controls can move an arm)')
    parser.add_argument('--view-port', type=int, default=VIEW_PORT,
                        help='port of the view (default %(default)s)')
    args = parser.parse_args(argv)
    try:
        robots = backend(args.backend, args.port)
        nodes = system_nodes(args.system, robots, args.log_level, args.camera_transport)
    except ValueError as error:
        parser.error(str(error))
    if args.view:
        view = live_view_node(robots, args.view_host, args.view_port)
        nodes += (view,)
        controls = ('controls enabled' if view.parameters['controls_enabled']
                    else 'controls disabled: hardware')
        print(f'[launch] live view: {live_view_url(view)} ({controls})', flush=True)
    if args.rviz:
        if args.in_process:
            parser.error('--rviz starts RViz and robot_state_publisher as processes: '
                         'not with --in-process')
        missing = [p for p in VISUALIZATION_PACKAGES if not is_installed(p)]
        if missing:
            parser.error(f'--rviz needs {", ".join(missing)} from a ROS 2 Jazzy install '
                         f'(source /opt/ros/jazzy/setup.bash), not found')
        nodes += visualization_nodes()
    os.environ.update(ros_environment())
    if args.in_process:
        launch_in_process(nodes, args.duration)
        return 0
    return launch(nodes, args.duration, args.on_exit, args.max_restarts)


if __name__ == '__main__':
    sys.exit(main())
