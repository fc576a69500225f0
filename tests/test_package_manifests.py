"""Every package.xml is honest: it declares what the package imports (and the packages whose
executables it starts), and nothing else.

Each manifest is parsed with catkin_pkg (what colcon and rosdep read); the package's Python
sources are scanned for imports; the two sets must agree, through the rosdep key of each
third-party module. Keys are ones that resolve in rosdistro (e.g. ``python3-rosbags-pip``).
"""

import ast
import pathlib
import sys

from catkin_pkg.package import parse_package
import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())

# Top-level Python module -> the rosdep key that installs it.
ROSDEP_KEYS = {
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'pinocchio': 'pinocchio',
    'cv2': 'python3-opencv',
    'matplotlib': 'python3-matplotlib',
    'mpl_toolkits': 'python3-matplotlib',  # ships with matplotlib
    'numba': 'python3-numba',
    'tqdm': 'python3-tqdm',
    'yaml': 'python3-yaml',
    'rosbags': 'python3-rosbags-pip',
    'serial': 'python3-serial',
}
# PyPI-only modules with no rosdep key we could verify: installed from requirements.txt, named in
# a comment of the package.xml instead of a key rosdep could not resolve.
PYPI_ONLY = {'cobs', 'dask', 'distributed', 'viser', 'websockets'}
# ROS packages whose Python module has the package's own name.
ROS_PACKAGES = {
    'rclpy', 'ament_index_python', 'builtin_interfaces', 'std_msgs', 'std_srvs',
    'sensor_msgs', 'geometry_msgs', 'nav_msgs', 'visualization_msgs', 'diagnostic_msgs',
    'rcl_interfaces', 'lifecycle_msgs', 'rosgraph_msgs', 'launch', 'launch_ros', *PACKAGES,
}
# Keys with no module to import (not checked for use).
NOT_IMPORTED = {'python3-pytest'}


def imported_modules(package: str) -> set[str]:
    """Top-level modules imported by the package's Python sources (not its tests)."""
    modules = set()
    for path in (REPO_ROOT / package / package).rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                modules.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split('.')[0])
    return {m for m in modules if m not in sys.stdlib_module_names}


def started_packages(package: str) -> set[str]:
    """Packages whose executables ``package`` starts: the bringup's systems and RViz."""
    if package != 'inflarm_bringup':
        return set()
    from inflarm_bringup.systems import SYSTEMS, Backend, live_view_node, visualization_nodes
    nodes = [n for make in SYSTEMS.values() for kind in ('sim', 'sim_mcu')
             for n in make(Backend(kind, '/tmp/mcu'))] + [live_view_node()]
    return {n.package for n in (*nodes, *visualization_nodes())} - {package}


def required_keys(package: str) -> set[str]:
    keys = started_packages(package)
    for module in imported_modules(package) - {package}:
        if module in ROS_PACKAGES:
            keys.add(module)
        elif module in ROSDEP_KEYS:
            keys.add(ROSDEP_KEYS[module])
        elif module in PYPI_ONLY:
            text = (REPO_ROOT / package / 'package.xml').read_text()
            assert module in text, f'{package}/package.xml: say where {module} comes from'
        else:
            raise AssertionError(f'{package} imports {module!r}: add its rosdep key to '
                                 'ROSDEP_KEYS (and to the package.xml)')
    return keys


@pytest.mark.parametrize('package', PACKAGES)
def test_package_xml_declares_exactly_what_the_package_imports(package):
    manifest = parse_package(str(REPO_ROOT / package / 'package.xml'))
    assert manifest.name == package
    assert manifest.package_format == 3
    assert any(e.tagname == 'build_type' and e.content == 'ament_python'
               for e in manifest.exports)
    declared = {d.name for d in manifest.exec_depends + manifest.build_depends
                + manifest.build_export_depends}
    required = required_keys(package)
    missing = required - declared
    unused = declared - required - NOT_IMPORTED
    assert not missing, f'{package}/package.xml lacks exec_depend on {sorted(missing)}'
    assert not unused, f'{package}/package.xml declares {sorted(unused)}, which it never imports'


def test_rosdep_keys_are_the_resolvable_ones():
    # rosdistro has no python3-rosbags; rosbags from PyPI is python3-rosbags-pip.
    for package in PACKAGES:
        text = (REPO_ROOT / package / 'package.xml').read_text()
        assert '<exec_depend>python3-rosbags</exec_depend>' not in text, package


ALGORITHMS = ('inflarm_control', 'inflarm_estimation', 'inflarm_planning', 'inflarm_vision')
HARDWARE = 'inflarm_hw'


@pytest.mark.parametrize('package', PACKAGES)
def test_dependencies_point_one_way(package):
    """The model at the bottom; algorithms and hardware/simulation side by side above it,
    neither importing the other (as ros2_control's controllers and hardware components); the
    system's tools on top, in inflarm_bringup."""
    imported = imported_modules(package) & set(PACKAGES)
    if package in ALGORITHMS:
        assert HARDWARE not in imported, f'{package} imports {HARDWARE}'
        assert 'inflarm_bringup' not in imported
    if package == HARDWARE:
        assert not imported & set(ALGORITHMS), f'{HARDWARE} imports {imported & set(ALGORITHMS)}'
    if package in ('inflarm_model', 'inflarm_msgs_json'):
        assert imported <= {'inflarm_model', 'inflarm_msgs_json'}, imported
