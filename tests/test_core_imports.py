"""Algorithm cores import without rclpy (only `nodes` and `ros` modules may pull it in), and
without matplotlib (plots import it when they draw).

The one test of this for every core module: the modules are discovered in each package, so a new
core is covered without a test of its own.
"""

import pathlib
import pkgutil
import subprocess
import sys

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())
ROS_MODULES = ('nodes', 'ros', 'ros_conversions')
# Imported by no core module at import time.
FORBIDDEN = ('rclpy', 'matplotlib')


def core_modules(package: str) -> list[str]:
    modules = [package]
    for info in pkgutil.walk_packages([str(REPO_ROOT / package / package)], prefix=package + '.'):
        if not any(part in ROS_MODULES for part in info.name.split('.')[1:]):
            modules.append(info.name)
    return modules


def test_the_cores_that_the_per_file_checks_named_are_covered():
    # The modules that had an import check of their own before this test took them over.
    covered = {m for package in PACKAGES for m in core_modules(package)}
    assert {
        'inflarm_model.elastostatics', 'inflarm_model.soft_arm', 'inflarm_model.kinematics',
        'inflarm_model.urdf', 'inflarm_model.link', 'inflarm_model.characterization',
        'inflarm_msgs_json', 'inflarm_msgs_json.schema_export', 'inflarm_control.pid_ilc',
        'inflarm_control.path_following', 'inflarm_control.knowledge', 'inflarm_hw.sra_plant',
        'inflarm_hw.bridge', 'inflarm_hw.driver', 'inflarm_hw.mcu_protocol', 'inflarm_hw.valve',
    } <= covered


@pytest.mark.parametrize('package', PACKAGES)
def test_core_modules_import_without_rclpy_or_matplotlib(package):
    # One process per package (a process per module would add ~0.3 s of start-up each); each
    # module is checked right after its import, so a failure names the first module to pull
    # the forbidden one in.
    modules = core_modules(package)
    code = (
        'import importlib, sys\n'
        f'for name in {modules!r}:\n'
        '    importlib.import_module(name)\n'
        f'    for forbidden in {FORBIDDEN!r}:\n'
        "        assert forbidden not in sys.modules, f'{name} imports {forbidden}'\n"
    )
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
