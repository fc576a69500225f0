"""The ``launch/*.launch.py`` files, for ``ros2 launch`` on a ROS 2 Jazzy install.

Each file is one line, ``system_launch_description('<system>')``: the nodes come from the
table of `inflarm_bringup.systems` that ``inflarm-launch`` reads too, as launch_ros ``Node``
actions with the same parameter files, overrides, names and remappings, so the two ways of
starting a system cannot drift apart. Launch arguments (``ros2 launch inflarm_bringup
sim.launch.py backend:=sim_mcu rviz:=true``):

- ``backend``: ``sim`` (default), ``sim_mcu`` or ``hardware`` (`inflarm_bringup.systems`);
- ``port``: the MCU's serial device (``hardware``), or the pty link ``sim_mcu`` makes;
- ``rviz``: ``true`` adds `inflarm_bringup.systems.visualization_nodes` (robot_state_publisher,
  the static frames, rviz2 with ``rviz/inflarm.rviz``);
- ``log_level``: of every inflarm node (default ``info``);
- ``camera_transport``: ``raw`` or ``compressed``, the camera images from the simulated camera
  to ``ball_tracker`` (default ``''``: as the parameter files say, raw).

``launch`` and ``launch_ros`` are imported when a description is made, not with this module:
they are not on PyPI, and the rest of the package works without them.
"""

import os

from inflarm_bringup.processes import NodeProcess, overrides_file, ros_environment
from inflarm_bringup.systems import (
    BACKENDS,
    CAMERA_TRANSPORTS,
    backend,
    system_nodes,
    visualization_nodes,
)


def system_launch_description(system: str):
    """The LaunchDescription of ``system`` (a name of `inflarm_bringup.systems.SYSTEMS`)."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    return LaunchDescription([
        DeclareLaunchArgument('backend', default_value='sim', choices=list(BACKENDS),
                              description='the robots: simulators, the bridge on a simulated '
                                          'MCU, or the bridge on real hardware'),
        DeclareLaunchArgument('port', default_value='',
                              description='hardware: the MCU serial device; sim_mcu: the pty '
                                          'link to make (default: a fresh temporary path)'),
        DeclareLaunchArgument('rviz', default_value='false', choices=['true', 'false'],
                              description='start robot_state_publisher, the static frames '
                                          'and RViz'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='log level of every inflarm node'),
        DeclareLaunchArgument('camera_transport', default_value='',
                              choices=['', *CAMERA_TRANSPORTS],
                              description="camera images raw or JPEG-compressed; '': as "
                                          'configured (raw)'),
        OpaqueFunction(function=_system_actions, kwargs={'system': system}),
    ])


def _system_actions(context, system: str) -> list:
    arguments = context.launch_configurations
    nodes = system_nodes(system, backend(arguments['backend'], arguments['port']),
                         arguments['log_level'], arguments['camera_transport'] or None)
    if arguments['rviz'] == 'true':
        nodes += visualization_nodes()
    environment = {k: v for k, v in ros_environment().items() if os.environ.get(k) != v}
    return [launch_node(node, environment) for node in nodes]


def launch_node(node: NodeProcess, environment: dict[str, str] | None = None):
    """``node`` as a launch_ros ``Node``: what `NodeProcess.command` runs, for ``ros2 launch``."""
    from launch_ros.actions import Node

    parameters = node.parameter_files()
    if node.parameters:
        parameters.append(overrides_file(node.node_name, node.parameters))
    return Node(
        package=node.package, executable=node.executable, name=node.node_name,
        parameters=parameters, remappings=list(node.remappings.items()),
        arguments=list(node.arguments),
        ros_arguments=['--log-level', node.log_level] if node.log_level else [],
        additional_env=environment or None, output='screen', emulate_tty=True)
