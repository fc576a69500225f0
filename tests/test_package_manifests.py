"""Every package.xml is honest: it declares what the package imports (and the packages whose
executables it starts), and nothing else; and every key it declares resolves with rosdep.

Each manifest is parsed with catkin_pkg (what colcon and rosdep read); the package's Python
sources are scanned for imports; the two sets must agree, through the rosdep key of each
third-party module. The test package ``inflarm_tests`` (tests/package.xml) declares what the
suite imports, as test dependencies. Every key is a workspace package or a key of
``rosdep_keys.ROSDEP_SOURCES``, the table of where rosdistro defines it.
"""

import ast
import os
import pathlib
import sys
import xml.etree.ElementTree as ET

from catkin_pkg.package import parse_package
import pytest
import yaml

from rosdep_keys import ROSDEP_SOURCES

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())
TEST_PACKAGE = 'inflarm_tests'
MANIFESTS = {**{p: REPO_ROOT / p / 'package.xml' for p in PACKAGES},
             TEST_PACKAGE: REPO_ROOT / 'tests' / 'package.xml'}
DEPEND_TAGS = ('depend', 'build_depend', 'build_export_depend', 'buildtool_depend',
               'exec_depend', 'test_depend', 'doc_depend')

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
    'cobs': 'python-cobs-pip',
    # the test suite's
    'pytest': 'python3-pytest',
    'hypothesis': 'python3-hypothesis',
    'jsonschema': 'python3-jsonschema',
    'catkin_pkg': 'python3-catkin-pkg',
    'PIL': 'python3-pil',
    'skimage': 'python3-skimage',
}
# Modules from PyPI without a rosdep key that fits, installed from requirements.txt and named in
# a comment of the package.xml: viser, dask and distributed have no key in rosdistro; websockets
# comes with viser (viser needs >= 13.1; the key python3-websockets installs an older one, 10.4
# in Debian bookworm).
PYPI_ONLY = {'viser', 'websockets', 'dask', 'distributed'}
# ROS packages whose Python module has the package's own name.
ROS_PACKAGES = {
    'rclpy', 'ament_index_python', 'builtin_interfaces', 'std_msgs', 'std_srvs',
    'sensor_msgs', 'geometry_msgs', 'nav_msgs', 'visualization_msgs', 'diagnostic_msgs',
    'rcl_interfaces', 'lifecycle_msgs', 'rosgraph_msgs', 'launch', 'launch_ros', *PACKAGES,
}
# The test package's keys with no module to import: a pytest plugin (pyproject.toml's timeout)
# and the programs that two tests run (they skip without them, saying how to install them).
NOT_IMPORTED = {'python3-pytest-timeout', 'chromium-browser', 'iproute2'}


def sources(package: str) -> list[pathlib.Path]:
    """The package's Python sources; for the test package, the suite's (not its setup.py)."""
    if package == TEST_PACKAGE:
        suite = REPO_ROOT / 'tests'
        return sorted(set(suite.rglob('*.py')) - {suite / 'setup.py'})
    return sorted((REPO_ROOT / package / package).rglob('*.py'))


def imported_modules(package: str) -> set[str]:
    """Top-level modules imported by the package's Python sources, not its own or the stdlib's.

    The suite's own modules (``ros_harness``, ...) and the benchmarks' ``common`` (which
    test_benchmarks.py imports from benchmarks/) are the test package's own.
    """
    own = {'common', *(path.stem for path in sources(package))} if package == TEST_PACKAGE else ()
    modules = set()
    for path in sources(package):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                modules.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split('.')[0])
    return {m for m in modules if m not in sys.stdlib_module_names and m not in own}


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
            text = MANIFESTS[package].read_text()
            assert module in text, f'{package}/package.xml: say where {module} comes from'
        else:
            raise AssertionError(f'{package} imports {module!r}: add its rosdep key to '
                                 'ROSDEP_KEYS (and to the package.xml)')
    return keys


@pytest.mark.parametrize('package', [*PACKAGES, TEST_PACKAGE])
def test_package_xml_declares_exactly_what_the_package_imports(package):
    manifest = parse_package(str(MANIFESTS[package]))
    assert manifest.name == package
    assert manifest.package_format == 3
    assert any(e.tagname == 'build_type' and e.content == 'ament_python'
               for e in manifest.exports)
    if package == TEST_PACKAGE:
        declared = {d.name for d in manifest.test_depends}
        assert not manifest.exec_depends + manifest.build_depends, 'test dependencies only'
    else:
        declared = {d.name for d in manifest.exec_depends + manifest.build_depends
                    + manifest.build_export_depends}
        assert not manifest.test_depends, (
            f"{package} has no tests of its own: the suite's needs go to tests/package.xml")
    required = required_keys(package)
    missing = required - declared
    unused = declared - required - NOT_IMPORTED
    assert not missing, f'{package}/package.xml lacks a dependency on {sorted(missing)}'
    assert not unused, f'{package}/package.xml declares {sorted(unused)}, which it never imports'


def declared_keys(package: str) -> set[str]:
    """Every dependency key of the package.xml, of any kind."""
    root = ET.parse(MANIFESTS[package]).getroot()
    return {e.text.strip() for e in root if e.tag in DEPEND_TAGS}


@pytest.mark.parametrize('package', MANIFESTS)
def test_every_key_is_a_workspace_package_or_one_rosdistro_defines(package):
    unknown = declared_keys(package) - set(MANIFESTS) - set(ROSDEP_SOURCES)
    assert not unknown, (
        f'{package}/package.xml: {sorted(unknown)} not in tests/rosdep_keys.py; look the key up '
        'in ros/rosdistro (rosdep/*.yaml, jazzy/distribution.yaml) and add it with its source')


def test_the_rosdep_table_holds_only_keys_in_use():
    used = set().union(*map(declared_keys, MANIFESTS)) - set(MANIFESTS)
    assert sorted(set(ROSDEP_SOURCES) - used) == []
    # rosdistro has no python3-rosbags and no python3-cobs: PyPI's are the -pip keys.
    assert {'python3-rosbags', 'python3-cobs', 'python3-cobs-pip'}.isdisjoint(used)


ROSDISTRO_DIR = os.environ.get('ROSDISTRO_DIR')


@pytest.mark.skipif(not ROSDISTRO_DIR, reason='set ROSDISTRO_DIR to a ros/rosdistro checkout')
def test_the_rosdep_table_matches_rosdistro():
    root = pathlib.Path(ROSDISTRO_DIR)
    files = {name: yaml.safe_load((root / name).read_text())
             for name in {name for name, _ in ROSDEP_SOURCES.values()}}
    released = {package: repository
                for repository, entry in files['jazzy/distribution.yaml']['repositories'].items()
                if 'release' in entry
                for package in entry['release'].get('packages', [repository])}
    for key, (name, source) in ROSDEP_SOURCES.items():
        if name == 'jazzy/distribution.yaml':
            assert released.get(key) == source, key
        else:
            assert key in files[name], f'{key} not in {name}'
            assert files[name][key].get('ubuntu') == source, key


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
