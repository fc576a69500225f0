"""Algorithm cores import without rclpy: only `nodes` and `ros` modules may pull it in."""

import pathlib
import pkgutil
import subprocess
import sys

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())
ROS_MODULES = ('nodes', 'ros', 'ros_conversions')


def core_modules(package: str) -> list[str]:
    modules = [package]
    for info in pkgutil.walk_packages([str(REPO_ROOT / package / package)], prefix=package + '.'):
        if not any(part in ROS_MODULES for part in info.name.split('.')[1:]):
            modules.append(info.name)
    return modules


@pytest.mark.parametrize('package', PACKAGES)
def test_core_modules_import_without_rclpy(package):
    modules = core_modules(package)
    code = (
        'import importlib, sys\n'
        f'for name in {modules!r}:\n'
        '    importlib.import_module(name)\n'
        "    assert 'rclpy' not in sys.modules, name + ' imports rclpy'\n"
    )
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
