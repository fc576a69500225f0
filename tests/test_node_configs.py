"""Every config/<node>.yaml sets only parameters its node declares, with the declared types.

rclpy rejects a YAML integer for a double parameter at startup; this finds it before a user does.
"""

import importlib
import pathlib

import pytest
import yaml

from inflarm_model.nodes.arm_parameters import ARM_PARAMETERS

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
CONFIGS = sorted(REPO_ROOT.glob('inflarm_*/config/*.yaml'))  # fastdds_profile.xml aside
SHARED = {'inflatable_arm.yaml': ARM_PARAMETERS}  # files keyed /** for several nodes


def kind(value) -> str:
    if isinstance(value, list):
        return 'list of ' + (kind(value[0]) if value else 'anything')
    return type(value).__name__


PACKAGES = sorted(p.name for p in REPO_ROOT.glob('inflarm_*') if (p / 'package.xml').is_file())


def declared(config: pathlib.Path, node: str):
    """The parameter table of ``node``: in the config's package, or (a system's config in
    inflarm_bringup) in whichever package has that node."""
    if node == '/**':
        return SHARED[config.name]
    package = config.parents[1].name
    candidates = [package] + [p for p in PACKAGES if p != package]
    for name in candidates:
        if (REPO_ROOT / name / name / 'nodes' / f'{node}.py').is_file():
            return importlib.import_module(f'{name}.nodes.{node}').PARAMETERS
    raise AssertionError(f'{config.name}: no package has a node {node!r}')


@pytest.mark.parametrize('config', CONFIGS, ids=lambda p: f'{p.parents[1].name}/{p.name}')
def test_config_matches_the_declared_parameters(config):
    document = yaml.safe_load(config.read_text())
    for node, body in document.items():
        table = {p.name: p.default for p in declared(config, node)}
        values = body['ros__parameters']
        unknown = sorted(set(values) - set(table))
        assert not unknown, f'{config.name}: {node} declares no {unknown}'
        for name, value in values.items():
            if table[name] == [] or value == []:
                continue
            assert kind(value) == kind(table[name]), (
                f'{config.name}: {name} is {kind(value)}, declared {kind(table[name])}')

