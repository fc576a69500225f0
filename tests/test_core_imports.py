"""Algorithm cores import without rclpy (only `nodes` and `ros` modules may pull it in), and
without matplotlib (plots import it when they draw).

The one test of this for every core module: the modules are discovered in each package, so a new
core is covered without a test of its own.
"""

import json
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


@pytest.fixture(scope='module')
def first_imported_by() -> dict[str, list[str]]:
    """For each core module, the forbidden modules that first appeared with its import: every
    package's cores imported in one fresh process (a process per package cost 3-4 s each)."""
    modules = [m for package in PACKAGES for m in core_modules(package)]
    code = (
        'import importlib, json, sys\n'
        'found = {}\n'
        f'for name in {modules!r}:\n'
        f'    before = {{m for m in {FORBIDDEN!r} if m in sys.modules}}\n'
        '    importlib.import_module(name)\n'
        f'    found[name] = [m for m in {FORBIDDEN!r} if m in sys.modules and m not in before]\n'
        'print(json.dumps(found))\n'
    )
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])


@pytest.mark.parametrize('package', PACKAGES)
def test_core_modules_import_without_rclpy_or_matplotlib(package, first_imported_by):
    # Each module is checked right after its import, so a failure names the first module to
    # pull the forbidden one in.
    offenders = {m: found for m, found in first_imported_by.items()
                 if m in core_modules(package) and found}
    assert not offenders, f'core modules that import {FORBIDDEN}: {offenders}'
