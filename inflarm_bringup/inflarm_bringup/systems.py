"""The systems a user launches, as one table: which nodes, with which parameter files.

The Python launcher (``inflarm-launch``) and the standard ``launch/*.launch.py`` files both read
this table, so the two ways of starting a system cannot drift apart.

Systems:

- ``inflatable_arm``: the robot (``arm_sim``, or ``hw_bridge`` on an MCU), ``robot_description``,
  ``load_estimator``, ``elastostatic_ik``;
- ``soft_arm``: the robot (``sra_sim`` with its camera, or ``hw_bridge``), ``ball_tracker``,
  ``path_planner``, ``pressure_controller``;
- ``sim``: both (the default);
- ``smoke``: ``demo_joint_publisher`` and ``joint_state_monitor``, to check the tooling.

Backends, for the robots:

- ``sim`` (default): the simulators take the commands directly;
- ``sim_mcu``: ``hw_bridge`` in front of ``sim_mcu``, the simulated microcontroller on a
  pseudo-terminal: the hardware path, simulated;
- ``hardware``: ``hw_bridge`` on the serial port of a real MCU.

Camera transport (``--camera-transport``): ``raw`` or ``compressed`` sets the simulated camera's
``camera.transport`` (``sra_sim``, ``sim_mcu``) and ``ball_tracker``'s ``transport`` alike, so
that the images go as ``sensor_msgs/Image`` or as JPEG ``sensor_msgs/CompressedImage``; not
given, the nodes' parameter files decide (raw).

The live view (`live_view_node`, ``--view``): ``live_view`` serving both arms to a browser on
``http://<host>:<port>``, with its controls enabled on the simulated backends only.

Visualization (`visualization_nodes`, ``--rviz``): ``robot_state_publisher`` on the estimator's
deflected pose, the static frames (``world`` -> ``base_link``, ``world`` -> ``sra_mount``) and
``rviz2`` with ``rviz/inflarm.rviz``: nodes of a ROS 2 Jazzy install, not of PyPI.
"""

from collections.abc import Callable
from dataclasses import dataclass, replace
import os
import tempfile

from ament_index_python.packages import get_package_share_directory
import yaml

from inflarm_bringup.processes import NodeProcess, config_path

# The inflatable arm's geometry, stiffness and pressures, shared by every node that models it.
ARM_CONFIG = (('inflarm_model', 'inflatable_arm.yaml'),)
BACKENDS = ('sim', 'sim_mcu', 'hardware')
CAMERA_TRANSPORTS = ('raw', 'compressed')
# The parameter of each node that publishes or takes the camera images naming their transport.
_TRANSPORT_PARAMETERS = {'sra_sim': 'camera.transport', 'sim_mcu': 'camera.transport',
                         'ball_tracker': 'transport'}


@dataclass(frozen=True)
class Backend:
    """Where the robots' commands go: ``kind`` in `BACKENDS`; ``port`` for ``sim_mcu`` (the
    link ``sim_mcu`` makes to its pty) and ``hardware`` (the MCU's serial device)."""

    kind: str = 'sim'
    port: str = ''

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise ValueError(f'backend must be one of {list(BACKENDS)}, got {self.kind!r}')
        if self.kind != 'sim' and not self.port:
            raise ValueError(f'backend {self.kind!r} needs a serial port')


def backend(kind: str = 'sim', port: str = '') -> Backend:
    """The backend ``kind`` on ``port``; for ``sim_mcu`` without one, a fresh path for the
    simulated MCU's pty link."""
    if kind == 'sim_mcu' and not port:
        port = os.path.join(tempfile.mkdtemp(prefix='inflarm-mcu-'), 'mcu')
    return Backend(kind, port)


def _robots(plant: str, backend: Backend) -> tuple[NodeProcess, ...]:
    """The robot nodes: simulators, or the bridge (and, simulated, its MCU)."""
    if backend.kind == 'sim':
        arm = NodeProcess('inflarm_hw', 'arm_sim', shared_params=ARM_CONFIG)
        sra = NodeProcess('inflarm_hw', 'sra_sim',
                          system_params=(('inflarm_bringup', 'soft_arm.yaml'),))
        return {'arm': (arm,), 'sra': (sra,), 'both': (arm, sra)}[plant]
    bridge = NodeProcess('inflarm_hw', 'hw_bridge', shared_params=ARM_CONFIG,
                         parameters={'port': backend.port, 'autostart': True})
    if backend.kind == 'hardware':
        return (bridge,)
    mcu = NodeProcess('inflarm_hw', 'sim_mcu', shared_params=ARM_CONFIG,
                      system_params=(('inflarm_bringup', 'soft_arm.yaml'),),
                      parameters={'plant': plant, 'link': backend.port})
    return (mcu, bridge)


def inflatable_arm(backend: Backend = Backend(), plant: str = 'arm') -> tuple[NodeProcess, ...]:  # noqa: B008
    return (
        NodeProcess('inflarm_model', 'robot_description', shared_params=ARM_CONFIG),
        *_robots(plant, backend),
        NodeProcess('inflarm_estimation', 'load_estimator', shared_params=ARM_CONFIG),
        NodeProcess('inflarm_control', 'elastostatic_ik', shared_params=ARM_CONFIG),
    )


def soft_arm(backend: Backend = Backend(), plant: str = 'sra') -> tuple[NodeProcess, ...]:  # noqa: B008
    system = (('inflarm_bringup', 'soft_arm.yaml'),)
    return (
        *_robots(plant, backend),
        NodeProcess('inflarm_vision', 'ball_tracker', system_params=system),
        NodeProcess('inflarm_planning', 'path_planner', system_params=system),
        NodeProcess('inflarm_control', 'pressure_controller', system_params=system),
    )


def sim(backend: Backend = Backend()) -> tuple[NodeProcess, ...]:  # noqa: B008
    """Both arms; with a bridge, one MCU drives both robots."""
    arm = inflatable_arm(backend, 'both')
    robots = _robots('both', backend)
    return arm + tuple(n for n in soft_arm(backend, 'both') if n not in robots)


def smoke(backend: Backend = Backend()) -> tuple[NodeProcess, ...]:  # noqa: B008
    return (NodeProcess('inflarm_hw', 'demo_joint_publisher'),
            NodeProcess('inflarm_hw', 'joint_state_monitor'))


SYSTEMS: dict[str, Callable[[Backend], tuple[NodeProcess, ...]]] = {
    'sim': sim,
    'inflatable_arm': inflatable_arm,
    'soft_arm': soft_arm,
    'smoke': smoke,
}
"""System name -> the nodes of the system on a backend; the first is the default."""


def system_nodes(name: str, backend: Backend = Backend(), log_level: str | None = None,  # noqa: B008
                 camera_transport: str | None = None) -> tuple[NodeProcess, ...]:
    """The nodes of the system ``name``, with ``log_level`` set on each if given, and the
    camera images sent as ``camera_transport`` (one of `CAMERA_TRANSPORTS`) if given."""
    if name not in SYSTEMS:
        raise ValueError(f'system must be one of {list(SYSTEMS)}, got {name!r}')
    if camera_transport is not None and camera_transport not in CAMERA_TRANSPORTS:
        raise ValueError(f'camera transport must be one of {list(CAMERA_TRANSPORTS)}, got '
                         f'{camera_transport!r}')
    nodes = SYSTEMS[name](backend)
    if camera_transport is not None:
        nodes = tuple(replace(n, parameters={
            **n.parameters, _TRANSPORT_PARAMETERS[n.executable]: camera_transport})
            if n.executable in _TRANSPORT_PARAMETERS else n for n in nodes)
    return tuple(replace(n, log_level=log_level) for n in nodes) if log_level else nodes


# Where the two arms stand in RViz's fixed frame: the inflatable arm's base at the origin, the
# soft arm's mount 1.2 m beside it and 1.5 m up, its z axis down (the SRA hangs from its mount).
STATIC_FRAMES = (
    ('world', 'base_link', (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
    ('world', 'sra_mount', (1.2, 0.0, 1.5), (1.0, 0.0, 0.0, 0.0)),
)
"""(parent, child, translation [m], rotation xyzw) of each static transform."""
VISUALIZATION_PACKAGES = ('robot_state_publisher', 'tf2_ros', 'rviz2')


VIEW_HOST, VIEW_PORT = '127.0.0.1', 8080


def live_view_node(backend: Backend = Backend(), host: str = VIEW_HOST,  # noqa: B008
                   port: int = VIEW_PORT) -> NodeProcess:
    """The live view of a system on ``backend``: its controls command the simulators, never
    hardware (set ``controls_enabled`` on the node to allow that)."""
    return NodeProcess('inflarm_bringup', 'live_view', parameters={
        'host': host, 'port': int(port), 'controls_enabled': backend.kind != 'hardware'})


def live_view_url(node: NodeProcess) -> str:
    """Where a browser finds the view of `live_view_node` (0.0.0.0: this machine's name)."""
    host = node.parameters['host']
    if host in ('0.0.0.0', '::', ''):
        import socket
        host = socket.gethostname()
    return f"http://{host}:{node.parameters['port']}"


def arm_parameters_from_file(path: str) -> dict:
    """The ``arm.*`` values a parameter file keyed ``/**`` (``inflatable_arm.yaml``) sets, with
    the table's defaults for the others.

    Raises
    ------
    ValueError
        If the file is unreadable, not such a parameter file, or its values are inconsistent.
    """
    try:
        with open(path) as file:
            given = yaml.safe_load(file)['/**']['ros__parameters']
    except (OSError, yaml.YAMLError, KeyError, TypeError) as error:
        raise ValueError(f'{path}: not a parameter file keyed /** ({error!r})') from error
    # The node-side table imports rclpy: only when asked, so that the launcher's core does not.
    from inflarm_model.nodes.arm_parameters import ARM_PARAMETERS, check_arm_parameters
    values = {p.name: given.get(p.name, p.default) for p in ARM_PARAMETERS}
    problem = check_arm_parameters(values)
    if problem is not None:
        raise ValueError(f'{path}: {problem}')
    return values


def rviz_config() -> str:
    """The installed RViz configuration: both arms, the load, the plan, the ball."""
    return os.path.join(get_package_share_directory('inflarm_bringup'), 'rviz', 'inflarm.rviz')


def visualization_nodes() -> tuple[NodeProcess, ...]:
    """What RViz needs besides the system: TF of the estimated deflected arm (its URDF from
    the shared arm configuration), the static frames, and rviz2 itself."""
    from inflarm_model.nodes.arm_parameters import urdf_from_parameters
    urdf = urdf_from_parameters(arm_parameters_from_file(config_path(*ARM_CONFIG[0])))
    frames = tuple(_static_frame(*frame) for frame in STATIC_FRAMES)
    return (
        # The deflected arm: all seven joints of the estimate. The node's own copy of the
        # description goes aside; robot_description publishes the system's.
        NodeProcess('robot_state_publisher', 'robot_state_publisher',
                    parameters={'robot_description': urdf},
                    remappings={'joint_states': 'estimated_joint_states',
                                'robot_description': 'robot_state_publisher/robot_description'}),
        *frames,
        NodeProcess('rviz2', 'rviz2', arguments=('-d', rviz_config())),
    )


def _static_frame(parent: str, child: str, xyz: tuple, xyzw: tuple) -> NodeProcess:
    names = ('--x', '--y', '--z', '--qx', '--qy', '--qz', '--qw')
    pairs = zip(names, (repr(float(v)) for v in (*xyz, *xyzw)), strict=True)
    return NodeProcess('tf2_ros', 'static_transform_publisher', name=f'{child}_frame',
                       arguments=(*(a for pair in pairs for a in pair),
                                  '--frame-id', parent, '--child-frame-id', child))
