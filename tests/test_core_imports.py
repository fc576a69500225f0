"""Algorithm cores import without rclpy (only `nodes` and `ros` modules may pull it in), and
without matplotlib (plots import it when they draw); no module imports itself through others.

The one test of this for every core module: the modules are discovered in each package, so a new
core is covered without a test of its own.
"""

import ast
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


def module_imports() -> dict[str, set[str]]:
    """Each module of the packages -> the modules of the packages it imports, at the top or
    inside a function (a late import only hides a cycle)."""
    files = {}
    for package in PACKAGES:
        for path in (REPO_ROOT / package / package).rglob('*.py'):
            parts = path.relative_to(REPO_ROOT / package).with_suffix('').parts
            files['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = path
    graph = {}
    for name, path in files.items():
        package = name if path.name == '__init__.py' else name.rpartition('.')[0]
        imported = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                imported.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ''
                if node.level:
                    parts = package.split('.')
                    base = '.'.join([*parts[:len(parts) - node.level + 1],
                                     *([node.module] if node.module else [])])
                # `from package import module` imports the module
                imported.update(f'{base}.{a.name}' if f'{base}.{a.name}' in files else base
                                for a in node.names)
        graph[name] = {m for m in imported if m in files and m != name}
    return graph


def test_no_module_imports_itself_through_others():
    graph = module_imports()
    assert 'inflarm_bringup.ros.lockstep' in graph and len(graph) > 100  # the walk found them

    def reaches(start: str) -> set[str]:
        seen, todo = set(), list(graph[start])
        while todo:
            m = todo.pop()
            if m not in seen:
                seen.add(m)
                todo.extend(graph[m])
        return seen

    cycles = sorted(m for m in graph if m in reaches(m))
    assert cycles == [], f'modules on an import cycle: {cycles}'
