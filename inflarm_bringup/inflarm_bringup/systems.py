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
"""

from collections.abc import Callable
from dataclasses import dataclass, replace

from inflarm_bringup.processes import NodeProcess

# The inflatable arm's geometry, stiffness and pressures, shared by every node that models it.
ARM_CONFIG = (('inflarm_model', 'inflatable_arm.yaml'),)
BACKENDS = ('sim', 'sim_mcu', 'hardware')


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


def system_nodes(name: str, backend: Backend = Backend(), log_level: str | None = None  # noqa: B008
                 ) -> tuple[NodeProcess, ...]:
    """The nodes of the system ``name``, with ``log_level`` set on each if given."""
    if name not in SYSTEMS:
        raise ValueError(f'system must be one of {list(SYSTEMS)}, got {name!r}')
    nodes = SYSTEMS[name](backend)
    return tuple(replace(n, log_level=log_level) for n in nodes) if log_level else nodes
