"""The installed launch/*.launch.py files start what inflarm-launch starts.

``launch`` and ``launch_ros`` are not on PyPI: the test puts recording stand-ins for the few
names the files use (LaunchDescription, DeclareLaunchArgument, OpaqueFunction, Node) in
``sys.modules``, loads each installed file, and runs its OpaqueFunction as ``ros2 launch``
would, with the declared defaults and the arguments given.
"""

import importlib.util
import os
import sys
import types

from ament_index_python.packages import get_package_share_directory
import pinocchio as pin
import pytest
import yaml

from inflarm_bringup.systems import (
    STATIC_FRAMES,
    SYSTEMS,
    backend,
    system_nodes,
    visualization_nodes,
)

LAUNCH_FILES = ('sim', 'inflatable_arm', 'soft_arm')


class Recorded:
    """A launch action: what it was constructed with."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


@pytest.fixture
def launch_modules(monkeypatch):
    classes = {name: type(name, (Recorded,), {}) for name in (
        'LaunchDescription', 'DeclareLaunchArgument', 'OpaqueFunction', 'Node')}
    modules = {
        'launch': {'LaunchDescription': classes['LaunchDescription']},
        'launch.actions': {'DeclareLaunchArgument': classes['DeclareLaunchArgument'],
                           'OpaqueFunction': classes['OpaqueFunction']},
        'launch_ros': {},
        'launch_ros.actions': {'Node': classes['Node']},
    }
    for name, members in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(members)
        monkeypatch.setitem(sys.modules, name, module)
    return classes


def run_launch_file(system: str, **arguments: str) -> list[Recorded]:
    """The Node actions the installed ``<system>.launch.py`` gives with ``arguments``."""
    path = os.path.join(get_package_share_directory('inflarm_bringup'), 'launch',
                        f'{system}.launch.py')
    spec = importlib.util.spec_from_file_location(f'{system}_launch', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    (entities,) = description.args
    declared = {e.args[0]: e.kwargs for e in entities if type(e).__name__ ==
                'DeclareLaunchArgument'}
    for name, value in arguments.items():
        choices = declared[name].get('choices')
        assert choices is None or value in choices, f'{name}:={value} not among {choices}'
    configurations = {name: d['default_value'] for name, d in declared.items()} | arguments
    (opaque,) = [e for e in entities if type(e).__name__ == 'OpaqueFunction']
    context = types.SimpleNamespace(launch_configurations=configurations)
    return opaque.kwargs['function'](context, **opaque.kwargs['kwargs'])


def assert_same_node(action: Recorded, node) -> None:
    launched = action.kwargs
    assert (launched['package'], launched['executable'], launched['name']) == (
        node.package, node.executable, node.node_name)
    files = launched['parameters']
    if node.parameters:
        *files, overrides = files
        with open(overrides) as file:
            assert yaml.safe_load(file) == {f'/**/{node.node_name}': {'ros__parameters': {
                k: list(v) if isinstance(v, tuple) else v for k, v in node.parameters.items()}}}
    assert files == node.parameter_files()
    assert launched['remappings'] == list(node.remappings.items())
    assert launched['arguments'] == list(node.arguments)
    assert launched['ros_arguments'] == (['--log-level', node.log_level] if node.log_level
                                         else [])


@pytest.mark.parametrize('system', LAUNCH_FILES)
def test_each_launch_file_starts_the_launcher_s_nodes_with_their_parameters(
        launch_modules, system):
    actions = run_launch_file(system, log_level='debug')
    nodes = system_nodes(system, backend('sim'), 'debug')
    assert len(actions) == len(nodes)
    for action, node in zip(actions, nodes, strict=True):
        assert_same_node(action, node)
    assert set(LAUNCH_FILES) <= set(SYSTEMS)


def test_the_hardware_path_simulated_gets_a_pty_link_of_its_own(launch_modules):
    actions = run_launch_file('soft_arm', backend='sim_mcu')
    by_name = {a.kwargs['name']: a for a in actions}
    assert {'sim_mcu', 'hw_bridge'} <= set(by_name) and 'sra_sim' not in by_name
    overrides = {}
    for name in ('sim_mcu', 'hw_bridge'):
        with open(by_name[name].kwargs['parameters'][-1]) as file:
            overrides[name] = yaml.safe_load(file)[f'/**/{name}']['ros__parameters']
    assert overrides['sim_mcu']['link'] == overrides['hw_bridge']['port'] != ''


def test_hardware_without_a_port_is_refused_naming_it(launch_modules):
    with pytest.raises(ValueError, match="backend 'hardware' needs a serial port"):
        run_launch_file('inflatable_arm', backend='hardware')


def test_rviz_adds_the_state_publisher_the_frames_and_rviz(launch_modules):
    actions = run_launch_file('sim', rviz='true')
    nodes = system_nodes('sim', backend('sim'), 'info') + visualization_nodes()
    for action, node in zip(actions, nodes, strict=True):
        assert_same_node(action, node)
    executables = [a.kwargs['executable'] for a in actions[-len(visualization_nodes()):]]
    assert executables == ['robot_state_publisher'] + ['static_transform_publisher'] * len(
        STATIC_FRAMES) + ['rviz2']


def test_robot_state_publisher_gets_the_configured_arm_on_the_estimated_pose():
    state_publisher = visualization_nodes()[0]
    assert state_publisher.remappings['joint_states'] == 'estimated_joint_states'
    model = pin.buildModelFromXML(state_publisher.parameters['robot_description'])
    assert model.nq == 7
    arm_yaml = os.path.join(get_package_share_directory('inflarm_model'), 'config',
                            'inflatable_arm.yaml')
    with open(arm_yaml) as file:
        length = yaml.safe_load(file)['/**']['ros__parameters']['arm.link_length_m']
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    pin.updateFramePlacements(model, data)
    # stretched out along x at zero angles: two links of the configured length
    tip = data.oMf[model.getFrameId('tip')].translation
    assert tip == pytest.approx([2 * length, 0.0, 0.0])


def test_the_rviz_config_is_installed_with_the_package():
    rviz = visualization_nodes()[-1]
    assert rviz.arguments[0] == '-d' and os.path.isfile(rviz.arguments[1])
